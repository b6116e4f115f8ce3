"""Fence items as a vehicle stores them: the polygons and circles an upload sends (inclusion
green, exclusion red), each named as the table and the monitor name it, and the return point,
in metres from the origin :func:`~alphafence.plots.common.map_frame` picks for them (the
build's map of the same fences has the same)."""

from __future__ import annotations

import numpy as np

from alphafence.plots.common import draw_polygons, map_frame, save_figure, subplots
from alphafence.plots.mapmarks import finish_map

INCLUSION = dict(edgecolor="#2e7d32", facecolor="#2e7d3212", lw=1.6)
EXCLUSION = dict(edgecolor="#c62828", facecolor="#c6282833", lw=1.3)


def fence_items_figure(fences, return_point, path, title="Fence items"):
    """Draw fence items (decoded) on a map and save the picture as PNG.

    Each item is named (largest first, as many as fit without one name over another).

    Parameters
    ----------
    fences : list of OnboardFence
        What :func:`alphafence.onboard.decode.decode_fence` made of the items; circles are
        drawn as circles (64 sides), polygons as ArduPilot reads them.
    return_point : tuple or None
        ``(lon, lat)`` of the fence's return point, drawn as a star.
    path : str or Path
        The PNG to write.
    title : str
        The figure's title.

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    geoms = [("keep_in" if f.inclusion else "keep_out", f.geometry()) for f in fences]
    coords = [p for f in fences for p in f.lonlat] + ([return_point] if return_point else [])
    frame = map_frame(geoms, fallback=coords)
    fig, ax = subplots(figsize=(9, 9))
    names = []
    for f in sorted(fences, key=lambda f: f.inclusion):  # inclusions on top: their edges show
        local = frame.geom_to_local(f.geometry())
        if f.shape == "polygon" and local.is_empty:  # no area: draw its outline
            xy = np.asarray(frame.to_local(*np.asarray(f.lonlat).T)).T
            ax.plot(*np.vstack([xy, xy[:1]]).T, color=EXCLUSION["edgecolor"], lw=1.0,
                    label="exclusion (stay out)")  # fmt: skip
            continue
        label = "inclusion (stay inside)" if f.inclusion else "exclusion (stay out)"
        draw_polygons(ax, local, label=label, **(INCLUSION if f.inclusion else EXCLUSION))
        names.append((f.short_name, local.area, local))
    if return_point is not None:
        x, y = frame.to_local(*return_point)
        ax.plot([float(x)], [float(y)], "*", color="#1565c0", ms=14, label="return point")
    ax.autoscale_view()
    finish_map(ax, frame, names, count=None, fontsize=7)
    ax.set_title(title, fontsize=10)
    return save_figure(fig, path)
