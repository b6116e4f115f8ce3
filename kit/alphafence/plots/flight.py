"""A flight on a map: the track, the full-resolution fences, the fence the vehicle held and the
monitor's events, in metres from the origin :func:`~alphafence.plots.common.map_frame` picks
for the fences (as on the build's map)."""

from __future__ import annotations

import numpy as np

from alphafence.plots.common import (
    KIND_LABEL,
    draw_polygons,
    kind_style,
    map_frame,
    save_figure,
    subplots,
)
from alphafence.plots.mapmarks import finish_map, site_names

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

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    track = np.asarray(track, dtype=float)
    frame = map_frame([(r.kind, r.geometry) for r in records], fallback=track)
    x, y = (np.asarray(v, dtype=float) for v in frame.to_local(track[:, 0], track[:, 1]))
    fig, ax = subplots(figsize=(9, 9))
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    for r in sorted(records, key=lambda r: order.get(r.kind, 3)):
        style = kind_style(r.kind, label=KIND_LABEL.get(r.kind, r.kind))
        draw_polygons(ax, frame.geom_to_local(r.geometry), **style)
    for f in onboard:
        color = "#2e7d32" if f.inclusion else "#1565c0"
        draw_polygons(ax, frame.geom_to_local(f.geometry()), label="onboard fence (vehicle's)",
                      edgecolor=color, facecolor="none", lw=1.6, ls=":")  # fmt: skip
    ax.plot(x, y, "-", color="#212121", lw=1.5, label="track")
    ax.plot(x[:1], y[:1], "^", color="#212121", ms=9, ls="none", label="take-off")
    marked = set()
    for e in events:
        key = e.get("level") if e["event"] == "level" else e["event"]
        if key not in EVENT_STYLE or "lat" not in e or "lon" not in e:
            continue
        if key in RANK and RANK[key] <= RANK.get(e.get("previous"), 0):
            continue  # a level coming down is not marked
        ex, ey = (float(v) for v in frame.to_local(e["lon"], e["lat"]))
        style = EVENT_STYLE[key]
        ax.plot(ex, ey, ls="none", ms=9, mec="white", mfc=style["color"], marker=style["marker"],
                label=None if key in marked else key)  # fmt: skip
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
        marked.add(key)
    ax.set_xlim(x.min() - MARGIN_M, x.max() + MARGIN_M)
    ax.set_ylim(y.min() - MARGIN_M, y.max() + MARGIN_M)
    finish_map(ax, frame, site_names(records, frame))
    ax.set_title(title)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    return save_figure(fig, path)
