"""A routed mission on a map: fences, roadmap, path, in metres from the origin
:func:`~alphafence.plots.common.map_frame` picks for the fences (as on the build's map)."""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.plots.common import (
    KIND_LABEL,
    KIND_STYLE,
    draw_polygons,
    map_frame,
    save_figure,
    subplots,
)
from alphafence.plots.mapmarks import finish_map, site_names


def route_figure(roadmap, route, path, frame, records=(), title=None):
    """Draw a route over its roadmap and save it as PNG.

    Keep-out fences, their clearance (dotted), warning layers, the roadmap's edges, the A*
    path (dashed) and the smoothed route with its start and goal.

    Parameters
    ----------
    roadmap : Roadmap
        The roadmap the route was found on.
    route : Route
        What ``Roadmap.route`` returned.
    path : str or Path
        The PNG to write.
    frame : LocalFrame
        The frame of the roadmap's metres (the planner's).
    records : list of FenceRecord
        The fences routed around: they fix the map's origin and name the largest sites.
    title : str, optional
        By default the route's length, legs and least clearance.

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    from matplotlib.collections import LineCollection

    mframe = map_frame(
        [(r.kind, r.geometry) for r in records], fallback=[frame.to_wgs84(*route.xy[0])]
    )

    def to_map(xy):  # the roadmap's metres -> the map's
        return np.column_stack(mframe.to_local(*frame.to_wgs84(xy[..., 0], xy[..., 1])))

    def geom(g):
        return shapely.transform(g, to_map)

    fig, ax = subplots(figsize=(9, 9))
    for g in roadmap.warning:
        draw_polygons(ax, geom(g), label=KIND_LABEL["warning"], **KIND_STYLE["warning"])
    for g in roadmap.keep_out:
        draw_polygons(ax, geom(g), label=KIND_LABEL["keep_out"], **KIND_STYLE["keep_out"])
    if roadmap.clearance > 0 and roadmap.keep_out.size:
        buf = shapely.union_all(shapely.buffer(roadmap.keep_out, roadmap.clearance))
        draw_polygons(ax, geom(buf), label=f"clearance ({roadmap.clearance:g} m)",
                      edgecolor="#c6282888", facecolor="none", lw=0.6, ls=":")  # fmt: skip
    V, E = roadmap.vertices, roadmap.edges
    if len(E):
        segs = to_map(np.stack([V[E[:, 0]], V[E[:, 1]]], axis=1).reshape(-1, 2)).reshape(-1, 2, 2)
        ax.add_collection(LineCollection(segs, colors="#9e9e9e", lw=0.4, label="roadmap"))
    if route.raw_xy is not None:
        raw = to_map(route.raw_xy)
        ax.plot(*raw.T, color="#1565c0", lw=0.8, ls="--", alpha=0.6, label="A* path")
    xy = to_map(route.xy)
    ax.plot(*xy.T, color="#1565c0", lw=2.0, marker=".", ms=5, label="route")
    ax.plot(*xy[0], "o", color="#2e7d32", ms=8, label="start", ls="none")
    ax.plot(*xy[-1], "*", color="#2e7d32", ms=12, label="goal", ls="none")
    pad = max(200.0, 0.15 * float(np.ptp(xy, axis=0).max()))
    lo, hi = xy.min(axis=0) - pad, xy.max(axis=0) + pad
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    finish_map(ax, mframe, site_names(records, mframe))
    ax.set_title(
        title
        or f"Route {route.length_m:.0f} m, {len(route.xy) - 1} legs, min clearance "
        f"{route.min_clearance_m:.1f} m (asked {roadmap.clearance:g} m)",
        fontsize=10,
    )
    return save_figure(fig, path)
