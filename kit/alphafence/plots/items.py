"""Fence items as a vehicle stores them: the polygons and circles an upload sends (inclusion
green, exclusion red), each named as the table and the monitor name it, and the return point."""

from __future__ import annotations

import numpy as np

from alphafence.geo.frame import LocalFrame
from alphafence.plots.common import draw_polygons, save_figure, subplots

INCLUSION = dict(edgecolor="#2e7d32", facecolor="#2e7d3212", lw=1.6)
EXCLUSION = dict(edgecolor="#c62828", facecolor="#c6282833", lw=1.3)


def fence_items_figure(fences, return_point, path, title="Fence items"):
    """Draw fence items (decoded) in metres around them and save the picture as PNG.

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
    """
    from matplotlib.lines import Line2D

    coords = [p for f in fences for p in f.lonlat] + ([return_point] if return_point else [])
    frame = LocalFrame.around_coords(np.asarray(coords, float))
    fig, ax = subplots(figsize=(9, 9))
    for f in sorted(fences, key=lambda f: f.inclusion):  # inclusions on top: their edges show
        local = frame.geom_to_local(f.geometry())
        if f.shape == "polygon" and local.is_empty:  # no area: draw its outline
            xy = np.asarray(frame.to_local(*np.asarray(f.lonlat).T)).T
            ax.plot(*np.vstack([xy, xy[:1]]).T, color=EXCLUSION["edgecolor"], lw=1.0)
            continue
        draw_polygons(ax, local, **(INCLUSION if f.inclusion else EXCLUSION))
        at = local.representative_point() if not local.is_empty else None
        if at is not None:
            ax.annotate(
                f.short_name,
                (at.x, at.y),
                xytext=(0, 9),
                textcoords="offset points",
                fontsize=7,
                ha="center",
                color="#212121",
            )
    handles = [
        Line2D([], [], color=INCLUSION["edgecolor"], label="inclusion (stay inside)"),
        Line2D([], [], color=EXCLUSION["edgecolor"], label="exclusion (stay out)"),
    ]
    if return_point is not None:
        x, y = frame.to_local(*return_point)
        ax.plot([float(x)], [float(y)], "*", color="#1565c0", ms=14)
        handles.append(
            Line2D([], [], color="#1565c0", marker="*", ls="none", ms=10, label="return point")
        )
    ax.legend(handles=handles, loc="best", fontsize=8)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(title, fontsize=10)
    save_figure(fig, path)
