"""A post-flight check on a map: the logged track over the fences, where it entered them
(red), its closest approaches to the fences it kept out of, and the fences that were not in
force when it flew (grey), in metres from the origin :func:`~alphafence.plots.common.map_frame`
picks for the fences (as on the build's map)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely

from alphafence.plots.common import (
    KIND_LABEL,
    draw_polygons,
    kind_style,
    map_frame,
    save_figure,
    subplots,
)
from alphafence.plots.mapmarks import finish_map, site_names

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
    """Draw a :class:`~alphafence.review.postflight.FlightReport` and save it as PNG.

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

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    fs, track = report.fences, report.track
    frame = map_frame([(r.kind, r.geometry) for r in fs.records], fallback=track[:, 1:3])
    x, y = (np.asarray(v, dtype=float) for v in frame.to_local(track[:, 1], track[:, 2]))
    fig, ax = subplots(figsize=(9, 9))
    near = _near(report)
    lo, hi = _view(frame, x, y, near)
    view = frame.geom_to_wgs84(shapely.box(*lo, *hi))
    shown = fs.tree.query(fs.frame.geom_to_local(view), predicate="intersects")
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    for k in sorted(shown.tolist(), key=lambda k: order.get(fs.records[k].kind, 3)):
        r = fs.records[k]
        never = report.in_force.get(k) == "no"
        label = "not in force then" if never else KIND_LABEL.get(r.kind, r.kind)
        style = dict(OFF_STYLE) if never else kind_style(r.kind)
        draw_polygons(ax, frame.geom_to_local(r.geometry), label=label, **style)
    ax.plot(x, y, "-", color="#212121", lw=1.3, zorder=3, label="track")
    if track[:, 4].any():
        red = np.where(track[:, 4] > 0, y, np.nan)
        ax.plot(x, red, "-", color="#c62828", lw=3.2, zorder=4,
                label="in a keep-out / out of a keep-in fence")  # fmt: skip
    ax.plot(x[:1], y[:1], "^", color="#212121", ms=9, zorder=5, ls="none", label="log's start")
    ax.plot(x[-1:], y[-1:], "s", color="#212121", ms=7, zorder=5, ls="none", label="log's end")
    for i, inc in enumerate(report.incursions):
        if inc.kind == "warning":
            continue
        ix, iy = (float(v) for v in frame.to_local(inc.lon, inc.lat))
        ax.plot(ix, iy, "X", ms=11, mfc="#c62828", mec="white", zorder=6, ls="none",
                label="incursion")  # fmt: skip
        what = "left" if inc.kind == "keep_in" else "entered"
        label = f"{what} {fs.records[inc.fence].site_id} {_clock(report, inc.t_in)}"
        ax.annotate(label, (ix, iy), xytext=(9, -4 - 11 * (i % 4)), textcoords="offset points",
                    fontsize=8, color="#b71c1c", zorder=7)  # fmt: skip
    for a in near:
        (ax_, bx), (ay, by) = (
            np.asarray(v, dtype=float) for v in frame.to_local([a.lon, a.fence_lon], [a.lat, a.fence_lat])
        )  # fmt: skip
        ax.plot([ax_, bx], [ay, by], ":", color="#1565c0", lw=1.2, zorder=5,
                label="closest approach")  # fmt: skip
        ax.annotate(f"{a.distance_m:.0f} m", ((ax_ + bx) / 2, (ay + by) / 2), xytext=(4, 4),
                    textcoords="offset points", fontsize=8, color="#0d47a1", zorder=7)  # fmt: skip
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    names = site_names([fs.records[k] for k in shown.tolist()], frame)
    finish_map(ax, frame, names)
    if title is None:
        verdict = "ENTERED a restricted zone" if report.entered else "no restricted zone entered"
        title = f"{Path(report.info.path).name}: {verdict}"
    ax.set_title(title)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    return save_figure(fig, path)
