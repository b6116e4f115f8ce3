"""A flight on a map: the track, the full-resolution fences, the fence the vehicle held and the
monitor's events, in metres east and north of the take-off point."""

from __future__ import annotations

import numpy as np

from alphafence.geo.frame import LocalFrame
from alphafence.plots.common import KIND_STYLE, draw_polygons, save_figure, subplots

#: Marker style per alert level and for commanded actions.
EVENT_STYLE = {
    "WARNING": dict(marker="o", color="#ef8f00"),
    "IMMINENT": dict(marker="s", color="#c62828"),
    "BREACH": dict(marker="X", color="#000000"),
    "action": dict(marker="v", color="#6a1b9a"),
}
RANK = {"CLEAR": 0, "WARNING": 1, "IMMINENT": 2, "BREACH": 3}
MARGIN_M = 250.0  # shown around the track


def flight_figure(records, onboard, track, events, path, title="Flight", note=None):
    """Draw a flight and save it as PNG.

    Parameters
    ----------
    records : list of FenceRecord
        The full-resolution fences (keep-out red, warning dashed orange, keep-in green).
    onboard : list of OnboardFence
        The fence the vehicle held (blue), as decoded from its items; may be empty.
    track : sequence of (lon, lat)
        Where the vehicle was, in order (at least one position).
    events : list of dict
        The monitor's events: those with a position (``lat``, ``lon``) that are ``level``
        changes up from OK, or ``action`` s, are marked and labelled.
    path : str or Path
        The PNG to write.
    title : str
        The figure's title.
    note : str, optional
        A line of small print at the bottom.
    """
    from matplotlib.lines import Line2D

    track = np.asarray(track, dtype=float)
    frame = LocalFrame(float(track[0, 0]), float(track[0, 1]))
    x, y = (np.asarray(v, dtype=float) for v in frame.to_local(track[:, 0], track[:, 1]))
    fig, ax = subplots(figsize=(9, 9))
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    for r in sorted(records, key=lambda r: order.get(r.kind, 3)):
        style = KIND_STYLE.get(r.kind, KIND_STYLE["keep_out"])
        draw_polygons(ax, frame.geom_to_local(r.geometry), **style)
    for f in onboard:
        color = "#2e7d32" if f.inclusion else "#1565c0"
        draw_polygons(
            ax, frame.geom_to_local(f.geometry()), edgecolor=color, facecolor="none", lw=1.6, ls=":"
        )
    ax.plot(x, y, "-", color="#212121", lw=1.5)
    ax.plot(x[:1], y[:1], "^", color="#212121", ms=9)
    handles = [
        Line2D([], [], color=KIND_STYLE["keep_out"]["edgecolor"], label="keep-out fence"),
        Line2D([], [], color=KIND_STYLE["warning"]["edgecolor"], ls="--", label="warning layer"),
        Line2D([], [], color="#1565c0", ls=":", lw=1.6, label="onboard fence (vehicle's)"),
        Line2D([], [], color="#212121", marker="^", label="track (from take-off)"),
    ]
    marked = set()
    for e in events:
        key = e.get("level") if e["event"] == "level" else e["event"]
        if key not in EVENT_STYLE or "lat" not in e or "lon" not in e:
            continue
        if key in RANK and RANK[key] <= RANK.get(e.get("previous"), 0):
            continue  # a level coming down is not marked
        ex, ey = (float(v) for v in frame.to_local(e["lon"], e["lat"]))
        style = EVENT_STYLE[key]
        ax.plot(ex, ey, ls="none", ms=9, mec="white", mfc=style["color"], marker=style["marker"])
        label = key if key != "action" else e.get("action", "action")
        if e.get("onboard_only"):
            label += " (onboard fence only)"
        ax.annotate(
            label,
            (ex, ey),
            xytext=(8, -4 - 11 * len(marked)),
            textcoords="offset points",
            fontsize=8,
        )
        if key not in marked:
            marked.add(key)
            handles.append(
                Line2D([], [], ls="none", marker=style["marker"], color=style["color"], label=key)
            )
    ax.set_xlim(min(x.min(), 0.0) - MARGIN_M, max(x.max(), 0.0) + MARGIN_M)
    ax.set_ylim(min(y.min(), 0.0) - MARGIN_M, max(y.max(), 0.0) + MARGIN_M)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east of take-off (m)")
    ax.set_ylabel("north of take-off (m)")
    ax.set_title(title)
    ax.legend(handles=handles, loc="upper left", fontsize=8)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    save_figure(fig, path)
