"""What every figure shares: matplotlib on the Agg backend (selected here and nowhere else),
the fence styles, the map frame every map is drawn in, drawing polygons, a legend beside the
map, and writing a figure atomically as PNG.

Maps are in metres east and north of a named origin, the same for every figure of one set of
fences (:func:`map_frame`): the centre of the bounds of its keep-out and keep-in fences,
rounded to 0.01° (0.1° when they span more than 50 km, 1° beyond 500 km), and written on the
axes (``east of 51.43°N 0.55°W (m)``), so a fence sits at the same coordinates in the build's
map, the items an upload sends, a route and a flight.
"""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import shapely  # noqa: E402

from alphafence.fencefiles.atomic import write_bytes_atomic  # noqa: E402
from alphafence.geo.frame import LocalFrame, wrap_lon  # noqa: E402

#: Matplotlib patch style per fence kind.
KIND_STYLE = {
    "keep_out": dict(edgecolor="#c62828", facecolor="#c6282822", lw=1.4),
    "warning": dict(edgecolor="#ef8f00", facecolor="none", lw=1.0, ls="--"),
    "keep_in": dict(edgecolor="#2e7d32", facecolor="none", lw=1.6),
}
#: Legend label per fence kind.
KIND_LABEL = {"keep_out": "keep-out fence", "warning": "warning layer", "keep_in": "keep-in fence"}
#: Line colour per fence method.
METHOD_COLOR = {"alpha": "#1565c0", "polygon": "#6a1b9a", "circle": "#ef6c00", "exact": "#2e7d32"}
#: Rounding of a map's origin (degrees) by the extent of its fences (metres, the larger side).
ORIGIN_STEPS = ((50_000.0, 0.01), (500_000.0, 0.1), (float("inf"), 1.0))
DPI = 130  # of the PNG written
PAD_INCHES = 0.1  # white space kept around everything drawn


class MapFrame(LocalFrame):
    """The frame a map is drawn in: metres east and north of a rounded origin that is named on
    the axes.

    Parameters
    ----------
    lon0, lat0 : float
        The origin, degrees.
    step : float
        The rounding of the origin, degrees (how many decimals its name shows).

    Examples
    --------
    >>> MapFrame(-0.55, 51.43, 0.01).origin
    '51.43°N 0.55°W'
    """

    __slots__ = ("step",)

    def __init__(self, lon0, lat0, step=0.01):
        super().__init__(lon0, lat0)
        self.step = float(step)

    @property
    def origin(self) -> str:
        """The origin's name: ``'51.43°N 0.55°W'``."""
        d = max(0, -int(np.floor(np.log10(self.step) + 1e-9)))
        lat, lon = round(self.lat0, d), round(self.lon0, d)
        ns, ew = "N" if lat >= 0 else "S", "E" if lon >= 0 else "W"
        return f"{abs(lat):.{d}f}°{ns} {abs(lon):.{d}f}°{ew}"

    def label_axes(self, ax, fontsize=None):
        """Name the origin on ``ax``'s axes: ``east of 51.43°N 0.55°W (m)`` and ``north of ...``."""
        ax.set_xlabel(f"east of {self.origin} (m)", fontsize=fontsize)
        ax.set_ylabel(f"north of {self.origin} (m)", fontsize=fontsize)


def map_frame(geoms, fallback=()):
    """The frame of the maps of a set of fences: see the module's docstring.

    Parameters
    ----------
    geoms : sequence of (kind, shapely geometry)
        The fences' kinds and WGS84 geometries; warning layers count only when there is
        nothing else.
    fallback : sequence of (lon, lat)
        Positions to centre on when there are no fences (a track, a route).

    Returns
    -------
    MapFrame

    Examples
    --------
    >>> import shapely
    >>> map_frame([("keep_out", shapely.box(14.501, 35.897, 14.512, 35.902))]).origin
    '35.90°N 14.51°E'
    """
    geoms = list(geoms)
    hard = [g for k, g in geoms if k != "warning"] or [g for _, g in geoms]
    coords = shapely.get_coordinates(np.asarray(hard, dtype=object)) if hard else np.empty((0, 2))
    if not len(coords):
        coords = np.asarray(fallback, float).reshape(-1, 2)
    if not len(coords):
        return MapFrame(0.0, 0.0, 1.0)
    centre = LocalFrame.around_coords(coords)
    x, y = centre.to_local(coords[:, 0], coords[:, 1])
    span = max(float(np.ptp(x)), float(np.ptp(y)))
    step = next(s for limit, s in ORIGIN_STEPS if span <= limit)
    lon0 = float(wrap_lon(np.round(centre.lon0 / step) * step))
    lat0 = float(np.clip(np.round(centre.lat0 / step) * step, -90.0, 90.0))
    return MapFrame(lon0, lat0, step)


def subplots(*args, **kwargs):
    """A new figure and its axes: :func:`matplotlib.pyplot.subplots` on the Agg backend.

    Returns
    -------
    fig : matplotlib.figure.Figure
    ax : matplotlib.axes.Axes or array of Axes
    """
    return plt.subplots(*args, **kwargs)


def draw_polygons(ax, geom, label=None, **style):
    """Add the polygons of ``geom`` (holes included) to ``ax`` as patches.

    Parts that are not polygons (points, lines) are skipped.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    geom : shapely geometry
        A Polygon, MultiPolygon or collection, in the axes' coordinates.
    label : str, optional
        The legend's entry for the first patch (entries come from what is drawn: nothing
        drawn, no entry).
    **style
        Passed to :class:`matplotlib.patches.PathPatch` (``edgecolor``, ``facecolor``, ``lw``...).

    Returns
    -------
    list of matplotlib.patches.PathPatch
    """
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path

    patches = []
    for poly in _parts(geom):
        if poly.geom_type != "Polygon" or poly.is_empty:
            continue
        rings = [np.asarray(poly.exterior.coords)] + [np.asarray(r.coords) for r in poly.interiors]
        verts = np.concatenate(rings)
        codes = np.concatenate(
            [[Path.MOVETO] + [Path.LINETO] * (len(r) - 2) + [Path.CLOSEPOLY] for r in rings]
        )
        patch = PathPatch(Path(verts, codes), label=label if not patches else None, **style)
        patches.append(ax.add_patch(patch))
    return patches


def _parts(geom):
    """The single parts of ``geom`` (points, lines, polygons), however deeply nested."""
    parts = shapely.get_parts(geom)
    while any(p.geom_type.startswith(("Multi", "GeometryCollection")) for p in parts):
        parts = shapely.get_parts(parts)
    return parts


def draw_restricted(ax, geom, label="restricted area"):
    """Draw a restricted area in grey: its polygons filled, its points as dots and its lines
    as thin strokes; the first thing drawn carries the legend's ``label``."""
    for part in _parts(geom):
        if part.geom_type == "Point":
            ax.plot(part.x, part.y, "k.", ms=3, label=label)
            label = None
        elif part.geom_type == "LineString":
            ax.plot(*np.asarray(part.coords).T, color="#555", lw=1, label=label)
            label = None
    draw_polygons(ax, geom, label=label, edgecolor="#444", facecolor="#9e9e9e", lw=0.5)


def kind_style(kind, **extra):
    """The patch style of a fence kind (keep-out's for an unknown one), with ``extra``."""
    return {**KIND_STYLE.get(kind, KIND_STYLE["keep_out"]), **extra}


def legend_beside(ax, fontsize=8):
    """A legend of what ``ax`` shows, to the right of the map so that it covers nothing.

    Its entries are the labels of the artists drawn (each label once), so a kind that is not
    drawn has none.

    Returns
    -------
    matplotlib.legend.Legend or None
        None when nothing drawn has a label.
    """
    handles, labels = ax.get_legend_handles_labels()
    seen = {}
    for h, lab in zip(handles, labels):
        seen.setdefault(lab, h)
    if not seen:
        return None
    return ax.legend(
        list(seen.values()),
        list(seen),
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        borderaxespad=0.0,
        fontsize=fontsize,
    )


def saved_bbox(fig):
    """The part of ``fig`` :func:`save_figure` writes, in inches: everything drawn, padded."""
    renderer = fig.canvas.get_renderer()
    return fig.get_tightbbox(renderer).padded(PAD_INCHES)


def save_figure(fig, path):
    """Write ``fig`` to ``path`` as PNG (130 dpi, cropped to everything drawn: nothing is cut
    off), all or nothing, and close it.

    Returns
    -------
    matplotlib.figure.Figure
        ``fig``, closed (its artists can still be read).
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", pad_inches=PAD_INCHES)
    plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())
    return fig
