"""Fences around sites: alpha shape, convex polygon, circle, exact; warning layers.

All geometry here is metric (the site's LocalFrame). Every keep-out or warning fence is
checked to cover the site's restricted area buffered by its margin; a fence that fails the
check (which would be a bug or a numerical edge) is repaired by uniting it with the required
region, and reported.
"""

from __future__ import annotations

import gc
import math
from dataclasses import replace

import numpy as np
import shapely
from shapely.ops import polylabel

from alphafence.fencing import METHODS
from alphafence.fencing.as_read import (
    ground_margins,
    hold_fences,
    readable_fences,
    reads_covering,
    split_at_antimeridian,
)
from alphafence.fencing.budget import plain_polygons, simplify_parts
from alphafence.fencing.fence_types import Fence, FenceOptions
from alphafence.fencing.sites import circle_steps
from alphafence.fencing.zone_circle import zone_circle
from alphafence.geo.alpha import alpha_shape, fill_holes, outer_polygons
from alphafence.geo.outward import simplify_polygon
from alphafence.geo.rings import clear_of

PAD_M = 0.1  # slack for coordinate rounding (1e-7 degrees is about 1 cm)
QUAD_SEGS = 6
CIRCLE_SEGMENTS = 64


def required_region(geometry, margin_m):
    """A polygon that contains ``geometry`` buffered by ``margin_m`` (plus PAD_M)."""
    d = (margin_m + PAD_M) * circle_steps(QUAD_SEGS)
    return shapely.buffer(geometry, d, quad_segs=QUAD_SEGS)


def circle_polygon(x, y, r):
    """A 64-gon that contains the circle (circumscribed), metres."""
    ang = np.linspace(0, 2 * math.pi, CIRCLE_SEGMENTS, endpoint=False) + math.pi / CIRCLE_SEGMENTS
    r_out = r / math.cos(math.pi / CIRCLE_SEGMENTS)
    return shapely.Polygon(np.column_stack([x + r_out * np.cos(ang), y + r_out * np.sin(ang)]))


def enclosing_circle(region):
    """(x, y, r): a circle containing every vertex of ``region`` (so the whole polygon).

    Examples
    --------
    >>> import shapely
    >>> x, y, r = enclosing_circle(shapely.box(0, 0, 2, 2))
    >>> round(x, 6), round(y, 6), round(r, 6)
    (1.0, 1.0, 1.414215)
    """
    center = shapely.centroid(shapely.minimum_bounding_circle(region))
    pts = shapely.get_coordinates(region)
    cx, cy = center.x, center.y
    r = float(np.max(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy)))
    return cx, cy, r * (1 + 1e-9) + 1e-6


def outer_fence(region, opts):
    """An enclosing fence of ``region`` (metres) by ``opts.method``.

    Returns
    -------
    geometry : shapely geometry
    circle : tuple or None
        ``(x, y, r)`` for the circle method.
    alpha : float or None
        The alpha used by the alpha method.
    """
    return outer_fences([region], opts)[0]


def outer_fences(regions, opts):
    """:func:`outer_fence` of each region, their simplifications in one pass.

    Returns
    -------
    list of tuple
        ``(geometry, circle, alpha)`` per region.
    """
    method = opts.method
    if method == "alpha":
        regions = _array(regions)
        plain = plain_polygons(regions) & (opts.alpha_radius is None)  # one part: alpha 0
        made = [
            (r, 0.0) if one else alpha_shape(r, opts.alpha_radius)
            for r, one in zip(regions.tolist(), plain.tolist())
        ]
        shapes = simplify_parts([shape for shape, _ in made], opts)
        return [(f, None, alpha) for f, (_, alpha) in zip(shapes, made)]
    if method == "polygon":
        hulls = shapely.convex_hull(_array(regions))
        return [(f, None, None) for f in simplify_parts(hulls, opts)]
    if method == "circle":
        return [(circle_polygon(*c), c, None) for c in map(enclosing_circle, regions)]
    if method == "exact":
        return [(fill_holes(r), None, None) for r in regions]
    raise ValueError(f"unknown method {method!r} (expected one of {', '.join(METHODS)})")


def covers_required(fence_geom, circle, geometry, margin_m) -> bool:
    """Does the fence contain the restricted geometry buffered by its margin?

    Checked exactly, without approximating the buffer: the geometry lies inside the fence
    and at least ``margin_m`` from the fence's boundary (for a circle: every vertex of the
    geometry lies within radius - margin of the centre).
    """
    return contains_with_margin(fence_geom, circle, geometry, margin_m)


def contains_with_margin(fence_geom, circle, geometry, margin_m, slack=0.0) -> bool:
    """Whether ``geometry`` lies inside the fence and at least ``margin_m - slack`` from its
    boundary (for a circle fence, ``circle = (x, y, r)``: every vertex within
    ``r - margin_m + slack`` of the centre).

    Examples
    --------
    >>> import shapely
    >>> fence, house = shapely.box(-50, -50, 50, 50), shapely.box(-10, -10, 10, 10)
    >>> contains_with_margin(fence, None, house, 40.0), contains_with_margin(fence, None, house, 41.0)
    (True, False)
    """
    if circle is not None:
        pts = shapely.get_coordinates(geometry)
        d = np.hypot(pts[:, 0] - circle[0], pts[:, 1] - circle[1])
        return bool(np.all(d + margin_m <= circle[2] + slack))
    if not shapely.covers(fence_geom, geometry):
        return False
    if margin_m <= 0:
        return True
    return clear_of(shapely.boundary(fence_geom), geometry, margin_m - slack)


def site_properties(site) -> dict:
    """What a fence carries from its features beyond geometry: ED-269 restriction,
    reasons, vertical references and applicability (time windows)."""
    props = {}
    for f in site.features:
        for key in ("restriction", "reason", "applicability", "lower_reference", "upper_reference"):
            value = f.properties.get(key)
            if value not in (None, [], "") and key not in props:
                props[key] = value
    return props


def site_fences(site, opts: FenceOptions):
    """The fences of one site: its main fence, plus a warning layer for keep-out sites.

    Every keep-out and warning fence is checked to contain the restricted area with its
    margin, and united with the required region when the check fails (``repaired``). A
    keep-in fence lies inside the area shrunk by the margin.

    Parameters
    ----------
    site : Site
    opts : FenceOptions

    Returns
    -------
    list of Fence

    Raises
    ------
    ValueError
        A keep-in site that vanishes inside its margin.
    """
    return fence_sites([site], opts)


def fence_sites(sites, opts: FenceOptions) -> list:
    """The fences of many sites: :func:`site_fences` of each, one after another, made stage
    by stage for all of them (each stage's buffers and containment checks one GEOS call).

    Parameters
    ----------
    sites : list of Site
    opts : FenceOptions

    Returns
    -------
    list of Fence
        Each site's main fence, followed by its warning layer if it has one.

    Raises
    ------
    ValueError
        A keep-in site that vanishes inside its margin.
    """
    collect = gc.isenabled()
    gc.disable()  # hundreds of thousands of small tuples (simplification heaps), no cycles:
    try:  # the collector would only walk them, and every other live object, again and again
        return split_at_antimeridian(_fence_sites(sites, opts))
    finally:
        if collect:
            gc.enable()


def _fence_sites(sites, opts):
    out = [[] for _ in sites]
    todo, bases, geoms, margins, zones = [], [], [], [], []
    for k, site in enumerate(sites):
        margin = site.margin_m if opts.margin_m is None else opts.margin_m
        zone = zone_circle(site, margin, PAD_M)  # one circle zone: one circle item onboard
        base = _base(site)
        if site.kind == "keep_in":
            out[k].append(_keep_in(site, site.geometry, margin, opts, base, zone))
            continue
        todo.append(k)
        bases.append(base)
        geoms.append(site.geometry)
        margins.append(margin)
        zones.append(zone)
    steps = circle_steps(QUAD_SEGS)
    ground = ground_margins(geoms, margins)  # as wide on the ground as the rules say
    regions = shapely.buffer(
        _array(geoms), [(m + PAD_M) * steps for m in ground], quad_segs=QUAD_SEGS
    )
    fenced = iter(outer_fences([r for r, z in zip(regions, zones) if z is None], opts))
    made = [next(fenced) if z is None else (circle_polygon(*z), z, None) for z in zones]
    locals_, circles, alphas = (list(col) for col in zip(*made)) if made else ([], [], [])
    frames = [sites[k].frame for k in todo]
    if opts.method in ("alpha", "polygon"):
        locals_ = readable_fences(locals_, frames, regions, _resimplify(opts), opts.max_vertices)
    # as lon/lat will read them (not where the edges' bows are proven clear of the zones)
    locals_, held = hold_fences(locals_, frames, regions=regions, zones=(geoms, ground))
    repaired = [not ok for ok in _covers_required(locals_, circles, geoms, ground)]
    for i in (i for i, bad in enumerate(repaired) if bad):
        locals_[i], circles[i] = _repair(locals_[i], regions[i], frames[i])
    for i in (i for i, h in enumerate(held) if h and not repaired[i]):
        if not reads_covering(locals_[i], frames[i], geoms[i], ground[i]):
            locals_[i], circles[i] = _repair(locals_[i], regions[i], frames[i])
            repaired[i] = True
    mains = []
    growth = shapely.area(_array(locals_)) / np.maximum(shapely.area(regions), 1e-9)
    for i, k in enumerate(todo):
        method = opts.method if zones[i] is None else "circle"
        main = Fence(kind=sites[k].kind, method=method, margin_m=margins[i],
                     local=locals_[i], circle=circles[i], alpha_m=alphas[i],
                     repaired=repaired[i], growth=float(growth[i]), **bases[i])  # fmt: skip
        out[k].append(main)
        mains.append(main)
    warn = [i for i, k in enumerate(todo) if sites[k].kind == "keep_out"]
    if opts.warn_distance_m > 0 and warn:
        layers = _warning_layers(
            [mains[i] for i in warn], [geoms[i] for i in warn], opts, [ground[i] for i in warn]
        )
        for i, fence in zip(warn, layers):
            out[todo[i]].append(fence)
    return [f for fences in out for f in fences]


def _resimplify(opts):
    """``simplify(region, n)``: ``region``'s fence by ``opts`` at ``n`` vertices."""
    return lambda region, n: outer_fences([region], replace(opts, max_vertices=n))[0][0]


def _repair(local, region, frame):
    """A fence that failed its check united with its required region, held as read."""
    return hold_fences([fill_holes(shapely.union(local, region))], [frame])[0][0], None


def _base(site):
    return dict(
        site_id=site.site_id,
        name=site.name,
        category=site.category,
        alt_min_m=site.alt_min_m,
        alt_max_m=site.alt_max_m,
        sources=site.sources,
        frame=site.frame,
        properties=site_properties(site),
    )


def _array(geoms):
    arr = np.empty(len(geoms), dtype=object)
    arr[:] = geoms
    return arr


def _covers_required(fences, circles, geoms, margins):
    """:func:`covers_required` of each fence, the polygons' checks one GEOS call each."""
    if len(fences) < 8:  # a few: one call each costs less than the arrays
        return [covers_required(*a) for a in zip(fences, circles, geoms, margins)]
    ok = [c is not None and covers_required(f, c, g, m)
          for f, c, g, m in zip(fences, circles, geoms, margins)]  # fmt: skip
    poly = [i for i, c in enumerate(circles) if c is None]
    fence, geom = _array([fences[i] for i in poly]), _array([geoms[i] for i in poly])
    covered = shapely.covers(fence, geom)
    far = [k for k, i in enumerate(poly) if covered[k] and margins[i] > 0]
    clear = clear_of(shapely.boundary(fence[far]), geom[far], [margins[poly[k]] for k in far])
    for k, i in enumerate(poly):
        ok[i] = bool(covered[k])
    for k, c in zip(far, clear.tolist()):
        ok[poly[k]] = c
    return ok


def _warning_layers(mains, geoms, opts, ground):
    """The warning layer of each keep-out fence in ``mains``, around ``geoms`` (``ground``:
    the mains' margins as wide on the ground)."""
    warn = opts.warn_distance_m
    margins = ground_margins(geoms, [g + warn for g in ground])
    circles = [None if m.circle is None else (*m.circle[:2], m.circle[2] + warn) for m in mains]
    locals_ = _array([m.local for m in mains])
    if opts.method == "exact":
        grown = shapely.buffer(locals_, warn * circle_steps(QUAD_SEGS), quad_segs=QUAD_SEGS)
    else:  # mitred corners contain the round offset and add no arc vertices
        grown = shapely.buffer(locals_, warn, join_style="mitre", mitre_limit=4.0)
    polygonal = [i for i, c in enumerate(circles) if c is None]
    if opts.method == "exact":
        simplified = iter(grown[polygonal])
    else:
        simplified = iter(simplify_parts(grown[polygonal], opts))
    locals_ = [circle_polygon(*c) if c is not None else next(simplified) for c in circles]
    frames = [m.frame for m in mains]
    locals_, held = hold_fences(locals_, frames, regions=list(grown), zones=(geoms, margins))
    repaired = [not ok for ok in _covers_required(locals_, circles, geoms, margins)]
    for i, (bad, h) in enumerate(zip(repaired, held)):
        if bad or (h and not reads_covering(locals_[i], frames[i], geoms[i], margins[i])):
            region = required_region(geoms[i], margins[i])
            locals_[i], circles[i] = _repair(locals_[i], region, frames[i])
            repaired[i] = True
    return [
        Fence(
            kind="warning",
            method=m.method,
            margin_m=m.margin_m + warn,
            local=locals_[i],
            circle=circles[i],
            alpha_m=m.alpha_m,
            repaired=repaired[i],
            **{k: getattr(m, k) for k in _BASE},
        )  # fmt: skip
        for i, m in enumerate(mains)
    ]


_BASE = ("site_id", "name", "category", "alt_min_m", "alt_max_m", "sources", "frame", "properties")


def _keep_in(site, geometry, margin, opts, base, zone=None):
    """A keep-in fence lies inside the area shrunk by the margin (inward simplification); a
    circle zone's is the circle ``zone`` (a disc inside it)."""
    if zone is not None:
        disc = shapely.Point(zone[0], zone[1]).buffer(zone[2], quad_segs=16)
        return Fence(
            kind="keep_in", method="circle", margin_m=margin, local=disc, circle=zone, **base
        )
    d = (margin + PAD_M) * circle_steps(QUAD_SEGS)
    inner = shapely.buffer(geometry, -d, quad_segs=QUAD_SEGS)
    circle = None
    if inner.is_empty:
        raise ValueError(f"keep-in site {site.site_id} vanishes inside its {margin} m margin")
    polys = outer_polygons(inner)
    if len(polys) > 1:  # a keep-in fence is one area: keep the largest part
        polys = polys[[int(np.argmax(shapely.area(polys)))]]
    poly = shapely.Polygon(polys[0].exterior)
    if opts.method == "circle":
        # the pole of inaccessibility (GEOS's maximum inscribed circle from shapely 2.1 on,
        # which shapely 2.0 lacks; polylabel is either), at the tolerance GEOS defaults to
        x0, y0, x1, y1 = polys[0].bounds
        centre = polylabel(polys[0], max(x1 - x0, y1 - y0) / 1000)
        cx, cy = centre.x, centre.y
        r = float(polys[0].boundary.distance(centre)) - PAD_M
        circle = (cx, cy, r)
        local = shapely.Point(cx, cy).buffer(r, quad_segs=16)
    elif opts.method == "exact":
        local = poly
    else:
        local = simplify_polygon(poly, opts.max_vertices, opts.tolerance_m, outward=False)
    local = hold_fences([local], [site.frame], outward=False)[0][0]  # inside, as read
    return Fence(
        kind="keep_in", method=opts.method, margin_m=margin, local=local, circle=circle, **base
    )
