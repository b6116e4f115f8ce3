"""The fence methods side by side on a few telling sites."""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.plots.common import (
    METHOD_COLOR,
    MapFrame,
    draw_polygons,
    draw_restricted,
    save_figure,
    subplots,
)
from alphafence.plots.mapmarks import add_scale_bar


def comparison_figure(sites, by_method, path, note=None):
    """Draw a grid of fences, one row per site and one column per method, and save it as PNG.

    Axes are metric (each site's frame, centred on the site, whose centre the row names) and a
    row shares one extent, so areas compare by eye; each panel has a scale bar, and its title
    gives the fence's vertices and its overshoot (fence area outside the restricted area, as a
    share of the restricted area).

    Parameters
    ----------
    sites : list of Site
        The rows (e.g. ``telling_sites(comparison)``).
    by_method : dict
        ``{method: {site_id: Fence}}``, as ``Comparison.fences``.
    path : str or Path
        The PNG to write.
    note : str, optional
        A line of small print at the bottom.

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    methods = list(by_method)
    fig, axes = subplots(
        len(sites), len(methods), figsize=(3.2 * len(methods), 3.2 * len(sites)), squeeze=False
    )
    for r, site in enumerate(sites):
        for c, m in enumerate(methods):
            ax = axes[r][c]
            fence = by_method[m][site.site_id]
            draw_polygons(
                ax,
                fence.local,
                edgecolor=METHOD_COLOR.get(m, "k"),
                facecolor=METHOD_COLOR.get(m, "k") + "22",
                lw=1.5,
            )
            draw_restricted(ax, site.geometry)
            ax.autoscale_view()
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            g = site.geometry.area
            over = (
                (fence.area_m2 - shapely.intersection(fence.local, site.geometry).area) / g
                if g
                else 0
            )
            ax.set_title(f"{m}: {fence.vertices} v, +{100 * over:.0f}%", fontsize=9)
            if c == 0:
                label = site.name or site.site_id
                label = label if len(label) <= 40 else label[:39] + "…"
                centre = MapFrame(site.frame.lon0, site.frame.lat0, 0.0001).origin
                ax.set_ylabel(f"{label}\n({site.category})\ncentred on {centre}", fontsize=8)
        # the same extent across a row, so areas compare by eye
        boxes = np.array([axes[r][c].dataLim.bounds for c in range(len(methods))])
        x0, y0 = boxes[:, 0].min(), boxes[:, 1].min()
        x1 = (boxes[:, 0] + boxes[:, 2]).max()
        y1 = (boxes[:, 1] + boxes[:, 3]).max()
        for c in range(len(methods)):
            axes[r][c].set_xlim(x0, x1)
            axes[r][c].set_ylim(y0, y1)
    for ax in np.ravel(axes):
        add_scale_bar(ax, fontsize=7)
    fig.suptitle("Fence methods side by side (grey: restricted area; +%: overshoot)", fontsize=11)
    if note:
        fig.text(0.01, 0.003, note, fontsize=7, color="#555")
    return save_figure(fig, path)
