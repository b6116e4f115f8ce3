"""What every figure shares: matplotlib on the Agg backend (selected here and nowhere else),
the fence styles, drawing polygons, and writing a figure atomically as PNG."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import shapely  # noqa: E402

from alphafence.formats.atomic import write_bytes_atomic  # noqa: E402

#: Matplotlib patch style per fence kind.
KIND_STYLE = {
    "keep_out": dict(edgecolor="#c62828", facecolor="#c6282822", lw=1.4),
    "warning": dict(edgecolor="#ef8f00", facecolor="none", lw=1.0, ls="--"),
    "keep_in": dict(edgecolor="#2e7d32", facecolor="none", lw=1.6),
}
#: Line colour per fence method.
METHOD_COLOR = {"alpha": "#1565c0", "polygon": "#6a1b9a", "circle": "#ef6c00", "exact": "#2e7d32"}


def subplots(*args, **kwargs):
    """A new figure and its axes: :func:`matplotlib.pyplot.subplots` on the Agg backend.

    Returns
    -------
    fig : matplotlib.figure.Figure
    ax : matplotlib.axes.Axes or array of Axes
    """
    return plt.subplots(*args, **kwargs)


def draw_polygons(ax, geom, **style):
    """Add the polygons of ``geom`` (holes included) to ``ax`` as patches.

    Parts that are not polygons (points, lines) are skipped.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    geom : shapely geometry
        A Polygon, MultiPolygon or collection, in the axes' coordinates.
    **style
        Passed to :class:`matplotlib.patches.PathPatch` (``edgecolor``, ``facecolor``, ``lw``...).
    """
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path

    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon":
            continue
        rings = [np.asarray(poly.exterior.coords)] + [np.asarray(r.coords) for r in poly.interiors]
        verts = np.concatenate(rings)
        codes = np.concatenate(
            [[Path.MOVETO] + [Path.LINETO] * (len(r) - 2) + [Path.CLOSEPOLY] for r in rings]
        )
        ax.add_patch(PathPatch(Path(verts, codes), **style))


def draw_restricted(ax, geom):
    """Draw a restricted area in grey: its polygons filled, its points as dots and its lines
    as thin strokes."""
    for part in shapely.get_parts(geom):
        if part.geom_type == "Point":
            ax.plot(part.x, part.y, "k.", ms=3)
        elif part.geom_type == "LineString":
            ax.plot(*np.asarray(part.coords).T, color="#555", lw=1)
    draw_polygons(ax, geom, edgecolor="#444", facecolor="#9e9e9e", lw=0.5)


def save_figure(fig, path):
    """Write ``fig`` to ``path`` as PNG (130 dpi, tight), all or nothing, and close it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())
