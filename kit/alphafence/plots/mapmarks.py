"""Marks on a map: a scale bar in its emptiest corner, the names of the largest sites (with a
white halo, none over another), and :func:`finish_map`, which adds them with the named origin
and the legend beside the map."""

from __future__ import annotations

import math

import numpy as np
import shapely

from alphafence.plots.common import legend_beside

NAMES = 10  # the largest sites named on a map
CORNERS = ("lower left", "lower right", "upper left", "upper right")
#: Where a name may go around its site, in points: (dx, dy, ha, va), tried in order.
NAME_SPOTS = (
    (0, 0, "center", "center"),
    (0, 7, "center", "bottom"),
    (0, -7, "center", "top"),
    (7, 0, "left", "center"),
    (-7, 0, "right", "center"),
)


def nice_length(width):
    """The scale bar's length for a map ``width`` metres wide: 1, 2 or 5 × 10^n, the one
    closest to a fifth of the width.

    Examples
    --------
    >>> nice_length(2600.0), nice_length(480.0), nice_length(9.0)
    (500.0, 100.0, 2.0)
    """
    target = max(float(width), 1e-9) / 5.0
    n = math.floor(math.log10(target))
    options = [m * 10.0**k for k in (n, n + 1) for m in (1, 2, 5)]
    return min(options, key=lambda v: abs(math.log(v / target)))


def length_label(metres):
    """``'500 m'``, ``'2 km'``.

    Examples
    --------
    >>> length_label(500.0), length_label(2000.0)
    ('500 m', '2 km')
    """
    return f"{metres / 1000:g} km" if metres >= 1000 else f"{metres:g} m"


def _drawn_points(ax):
    """The vertices of what ``ax`` shows, in display coordinates."""
    pts = [np.empty((0, 2))]
    for p in ax.patches:
        pts.extend(np.asarray(v, float) for v in p.get_verts() if len(v))
    for line in ax.lines:
        pts.append(line.get_transform().transform(np.asarray(line.get_xydata(), float)))
    for c in ax.collections:
        for seg in getattr(c, "get_segments", list)():
            pts.append(c.get_transform().transform(np.asarray(seg, float)))
    pts = np.concatenate([p.reshape(-1, 2) for p in pts])
    return pts[np.isfinite(pts).all(axis=1)]


def emptiest_corner(ax, share=(0.35, 0.15)):
    """The corner of ``ax`` with the fewest vertices drawn in its ``share`` of the width and
    height (lower left on a tie)."""
    box = ax.get_window_extent()
    pts = _drawn_points(ax)
    w, h = box.width * share[0], box.height * share[1]

    def load(corner):
        v, u = corner.split()
        x0 = box.x0 if u == "left" else box.x1 - w
        y0 = box.y0 if v == "lower" else box.y1 - h
        inside = (pts[:, 0] >= x0) & (pts[:, 0] <= x0 + w) & (pts[:, 1] >= y0)
        return int((inside & (pts[:, 1] <= y0 + h)).sum())

    return min(CORNERS, key=load)


def add_scale_bar(ax, fontsize=8):
    """A scale bar (:class:`~mpl_toolkits.axes_grid1.anchored_artists.AnchoredSizeBar`) about
    a fifth of the map's width (:func:`nice_length`), in its emptiest corner.

    ``ax`` is in metres; its limits and aspect are final.

    Returns
    -------
    AnchoredSizeBar
    """
    from matplotlib.font_manager import FontProperties
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    ax.apply_aspect()
    width = abs(float(np.diff(ax.get_xlim())[0]))
    length = nice_length(width)
    bar = AnchoredSizeBar(
        ax.transData,
        length,
        length_label(length),
        emptiest_corner(ax),
        pad=0.3,
        borderpad=0.5,
        sep=3,
        size_vertical=width / 250.0,
        color="#212121",
        fontproperties=FontProperties(size=fontsize),
    )
    bar.patch.set(facecolor="white", alpha=0.8, edgecolor="none")
    ax.add_artist(bar)
    return bar


def site_names(records, frame, limit=4 * NAMES):
    """What :func:`name_sites` needs of fences: ``(name, area m², geometry in metres)`` for
    the ``limit`` largest sites (a site's fences and warning layers united).

    Parameters
    ----------
    records : iterable
        Fences with ``kind``, ``site_id``, ``name`` and a WGS84 ``geometry``
        (:class:`~alphafence.fencefiles.fence_geojson.FenceRecord` or
        :class:`~alphafence.fencing.fence_types.Fence`).
    frame : LocalFrame
        The map's frame.
    limit : int
        How many sites to return: those whose fences add up to the largest areas (a
        country's fences are not all united to name ten).

    Returns
    -------
    list of tuple
    """
    records = list(records)
    if not records:
        return []
    local = frame.geom_to_local(np.asarray([r.geometry for r in records], dtype=object))
    by_site = {}
    for r, g, area in zip(records, local, shapely.area(local)):
        entry = by_site.setdefault(r.name or r.site_id, [0.0, []])
        entry[0] += area
        entry[1].append(g)
    largest = sorted(by_site.items(), key=lambda kv: -kv[1][0])[:limit]
    out = []
    for name, (_, geoms) in largest:
        united = shapely.union_all(geoms)
        out.append((name if len(name) <= 32 else name[:31] + "…", united.area, united))
    return out


def name_sites(ax, sites, count=NAMES, fontsize=8):
    """Name the ``count`` largest ``sites`` in view, each on its site (when it fits in the
    site's box) or beside it, with a white halo, none over another text on the map or its
    scale bar (a name with no free spot is left out).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Its limits and aspect final.
    sites : iterable of (str, float, shapely geometry)
        Name, area (the order of naming) and geometry in the axes' coordinates.
    count : int or None
        None: every site that fits.

    Returns
    -------
    list of matplotlib.text.Annotation
    """
    from matplotlib import patheffects

    ax.apply_aspect()
    renderer = ax.figure.canvas.get_renderer()
    box = ax.get_window_extent(renderer)
    (x0, x1), (y0, y1) = np.sort(ax.get_xlim()), np.sort(ax.get_ylim())
    view = shapely.box(x0, y0, x1, y1)
    taken = [a.get_window_extent(renderer) for a in [*ax.artists, *ax.texts]]
    halo = [patheffects.withStroke(linewidth=3, foreground="white")]
    placed, named = [], set()
    for name, _, geom in sorted(sites, key=lambda s: -s[1]):
        if count is not None and len(placed) >= count:
            break
        seen = shapely.intersection(geom, view) if not geom.is_empty else geom
        if name in named or seen.is_empty:
            continue
        at = seen.representative_point()
        site = ax.transData.transform(np.reshape(seen.bounds, (2, 2)))
        for dx, dy, ha, va in NAME_SPOTS:
            text = ax.annotate(name, (at.x, at.y), xytext=(dx, dy), textcoords="offset points",
                               ha=ha, va=va, fontsize=fontsize, color="#212121",
                               path_effects=halo, zorder=8)  # fmt: skip
            bb = text.get_window_extent(renderer)
            inside = box.x0 <= bb.x0 and bb.x1 <= box.x1 and box.y0 <= bb.y0 and bb.y1 <= box.y1
            on_site = (dx, dy) == (0, 0)  # only when the name fits inside the site's box
            fits = bb.width <= np.ptp(site[:, 0]) and bb.height <= np.ptp(site[:, 1])
            # 2 px apart at least: a final layout a pixel off must not make names touch
            apart = not any(bb.padded(2).overlaps(t) for t in taken)
            if inside and (fits or not on_site) and apart:
                taken.append(bb)
                placed.append(text)
                named.add(name)
                break
            text.remove()
    return placed


def _fit_limits(ax):
    """Widen ``ax``'s x or y limits about their centre so that a metre is as long on both."""
    box = ax.get_window_extent()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    per_x, per_y = (x1 - x0) / box.width, (y1 - y0) / box.height  # metres a pixel
    if per_x < per_y:
        half = 0.5 * per_y * box.width
        ax.set_xlim(0.5 * (x0 + x1) - half, 0.5 * (x0 + x1) + half)
    else:
        half = 0.5 * per_x * box.height
        ax.set_ylim(0.5 * (y0 + y1) - half, 0.5 * (y0 + y1) + half)


def finish_map(ax, frame, sites=(), count=NAMES, fontsize=8):
    """Make ``ax`` a map: equal scales, the origin of ``frame`` named on the axes, a scale
    bar, the names of the largest ``sites`` and the legend beside it.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        In metres of ``frame``, with its limits set (or to be found from what it shows).
    frame : MapFrame
    sites : iterable of (str, float, shapely geometry)
        As :func:`site_names` makes them.
    count : int or None
        How many sites to name (None: all that fit).

    Returns
    -------
    matplotlib.legend.Legend or None
    """
    if ax.get_autoscalex_on() or ax.get_autoscaley_on():
        ax.set_aspect("equal", adjustable="datalim")
    else:  # limits set: widen the narrower side to the axes' shape, keeping the centre
        _fit_limits(ax)
        ax.set_aspect("equal", adjustable="box")
    frame.label_axes(ax)
    ax.apply_aspect()
    add_scale_bar(ax, fontsize=fontsize)
    name_sites(ax, sites, count=count, fontsize=fontsize)
    return legend_beside(ax, fontsize=fontsize)
