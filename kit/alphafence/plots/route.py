"""A routed mission on a map (metres of the roadmap's frame): fences, roadmap, path."""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.plots.common import KIND_STYLE, draw_polygons, save_figure, subplots


def route_figure(roadmap, route, path, title=None):
    """Draw a route over its roadmap and save it as PNG, in metres of the roadmap's frame.

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
    title : str, optional
        By default the route's length, legs and least clearance.
    """
    from matplotlib.collections import LineCollection

    fig, ax = subplots(figsize=(9, 9))
    for g in roadmap.warning:
        draw_polygons(ax, g, **KIND_STYLE["warning"])
    for g in roadmap.keep_out:
        draw_polygons(ax, g, **KIND_STYLE["keep_out"])
    if roadmap.clearance > 0 and roadmap.keep_out.size:
        buf = shapely.union_all(shapely.buffer(roadmap.keep_out, roadmap.clearance))
        draw_polygons(ax, buf, edgecolor="#c6282888", facecolor="none", lw=0.6, ls=":")
    V, E = roadmap.vertices, roadmap.edges
    if len(E):
        ax.add_collection(
            LineCollection(np.stack([V[E[:, 0]], V[E[:, 1]]], axis=1), colors="#9e9e9e", lw=0.4)
        )
    if route.raw_xy is not None:
        ax.plot(*route.raw_xy.T, color="#1565c0", lw=0.8, ls="--", alpha=0.6, label="A* path")
    ax.plot(*route.xy.T, color="#1565c0", lw=2.0, marker=".", ms=5, label="route")
    ax.plot(*route.xy[0], "o", color="#2e7d32", ms=8, label="start")
    ax.plot(*route.xy[-1], "*", color="#2e7d32", ms=12, label="goal")
    pad = max(200.0, 0.15 * float(np.ptp(route.xy, axis=0).max()))
    lo = route.xy.min(axis=0) - pad
    hi = route.xy.max(axis=0) + pad
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(
        title
        or f"Route {route.length_m:.0f} m, {len(route.xy) - 1} legs, min clearance "
        f"{route.min_clearance_m:.1f} m (asked {roadmap.clearance:g} m)",
        fontsize=10,
    )
    save_figure(fig, path)
