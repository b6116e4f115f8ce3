"""A post-flight check on a map: the logged track over the fences, where it entered them
(red), its closest approaches to the fences it kept out of, and the fences that were not in
force when it flew (grey), in metres east and north of where the log starts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.plots.common import KIND_STYLE, draw_polygons, save_figure, subplots

MARGIN_M = 150.0  # shown around the track
OFF_STYLE = dict(edgecolor="#9e9e9e", facecolor="#9e9e9e18", lw=1.0, ls=":")
LABELLED_APPROACHES = 5  # the closest approaches drawn and labelled


def _clock(report, t):
    iso = report.when(t)
    return iso[11:19] if iso else f"T+{t:.0f} s"


def _near(report):
    """The closest approaches to keep-out fences in force and not entered: the few closest."""
    fs, entered = report.fences, {i.fence for i in report.incursions}
    return sorted(
        (
            a
            for k, a in report.closest.items()
            if k not in entered and a.in_force and fs.records[k].kind == "keep_out"
        ),
        key=lambda a: a.distance_m,
    )[:LABELLED_APPROACHES]


def _view(frame, x, y, near):
    """A square view of the track and the fence points of its closest approaches."""
    if near:
        fx, fy = frame.to_local([a.fence_lon for a in near], [a.fence_lat for a in near])
        x, y = np.r_[x, fx], np.r_[y, fy]
    cx, cy = (x.min() + x.max()) / 2, (y.min() + y.max()) / 2
    half = max(x.max() - x.min(), y.max() - y.min()) / 2 + MARGIN_M
    return (cx - half, cy - half), (cx + half, cy + half)


def flight_check_figure(report, path, title=None, note=None):
    """Draw a :class:`~alphafence.monitor.postflight.FlightReport` and save it as PNG.

    Parameters
    ----------
    report : FlightReport
        Its track (at least one position), fences, incursions and closest approaches.
    path : str or Path
        The PNG to write (all or nothing).
    title : str, optional
        Default: the log's name and the verdict.
    note : str, optional
        A line of small print at the bottom.
    """
    from matplotlib.lines import Line2D

    fs, track = report.fences, report.track
    frame = LocalFrame(float(track[0, 1]), float(track[0, 2]))
    x, y = (np.asarray(v, dtype=float) for v in frame.to_local(track[:, 1], track[:, 2]))
    fig, ax = subplots(figsize=(9, 9))
    near = _near(report)
    lo, hi = _view(frame, x, y, near)
    view = frame.geom_to_wgs84(shapely.box(*lo, *hi))
    shown = fs.tree.query(fs.frame.geom_to_local(view), predicate="intersects")
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    off = False
    for k in sorted(shown.tolist(), key=lambda k: order.get(fs.records[k].kind, 3)):
        r = fs.records[k]
        never = report.in_force.get(k) == "no"
        off |= never
        style = OFF_STYLE if never else KIND_STYLE.get(r.kind, KIND_STYLE["keep_out"])
        draw_polygons(ax, frame.geom_to_local(r.geometry), **style)
    ax.plot(x, y, "-", color="#212121", lw=1.3, zorder=3)
    red = np.where(track[:, 4] > 0, y, np.nan)
    ax.plot(x, red, "-", color="#c62828", lw=3.2, zorder=4)
    ax.plot(x[:1], y[:1], "^", color="#212121", ms=9, zorder=5)
    ax.plot(x[-1:], y[-1:], "s", color="#212121", ms=7, zorder=5)
    for i, inc in enumerate(report.incursions):
        if inc.kind == "warning":
            continue
        ix, iy = (float(v) for v in frame.to_local(inc.lon, inc.lat))
        ax.plot(ix, iy, "X", ms=11, mfc="#c62828", mec="white", zorder=6)
        what = "left" if inc.kind == "keep_in" else "entered"
        label = f"{what} {fs.records[inc.fence].site_id} {_clock(report, inc.t_in)}"
        ax.annotate(label, (ix, iy), xytext=(9, -4 - 11 * (i % 4)), textcoords="offset points",
                    fontsize=8, color="#b71c1c", zorder=7)  # fmt: skip
    for a in near:
        (ax_, bx), (ay, by) = (
            np.asarray(v, dtype=float) for v in frame.to_local([a.lon, a.fence_lon], [a.lat, a.fence_lat])
        )  # fmt: skip
        ax.plot([ax_, bx], [ay, by], ":", color="#1565c0", lw=1.2, zorder=5)
        ax.annotate(f"{a.distance_m:.0f} m", ((ax_ + bx) / 2, (ay + by) / 2), xytext=(4, 4),
                    textcoords="offset points", fontsize=8, color="#0d47a1", zorder=7)  # fmt: skip
    kinds = {fs.records[k].kind for k in shown.tolist() if report.in_force.get(k) != "no"}
    labels = {"keep_out": "keep-out fence", "warning": "warning layer", "keep_in": "keep-in fence"}
    handles = [
        Line2D([], [], color=KIND_STYLE[k]["edgecolor"], ls=KIND_STYLE[k].get("ls", "-"), label=v)
        for k, v in labels.items()
        if k in kinds
    ]
    handles.append(
        Line2D([], [], color="#212121", marker="^", label="track (from the log's start)")
    )
    if track[:, 4].any():
        handles.append(
            Line2D([], [], color="#c62828", lw=3.2, label="in a keep-out / out of a keep-in fence")
        )
    if off:
        handles.append(Line2D([], [], color="#9e9e9e", ls=":", label="not in force then"))
    if near:
        handles.append(Line2D([], [], color="#1565c0", ls=":", label="closest approach"))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east of the log's start (m)")
    ax.set_ylabel("north of the log's start (m)")
    if title is None:
        verdict = "ENTERED a restricted zone" if report.entered else "no restricted zone entered"
        title = f"{Path(report.info.path).name}: {verdict}"
    ax.set_title(title)
    ax.legend(handles=handles, loc="best", fontsize=8)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    save_figure(fig, path)
