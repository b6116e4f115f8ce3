"""Fences around sites: alpha shape, convex polygon, circle, exact; warning layers.

All geometry here is metric (the site's LocalFrame). Every keep-out or warning fence is
checked to cover the site's restricted area buffered by its margin; a fence that fails the
check (which would be a bug or a numerical edge) is repaired by uniting it with the required
region, and reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.ops import polylabel

from alphafence.build import METHODS
from alphafence.build.sites import circle_steps
from alphafence.build.zone_circle import zone_circle
from alphafence.geo.alpha import alpha_shape, fill_holes, outer_polygons
from alphafence.geo.outward import simplify_polygon

PAD_M = 0.1  # slack for coordinate rounding (1e-7 degrees is about 1 cm)
QUAD_SEGS = 6
CIRCLE_SEGMENTS = 64


@dataclass
class FenceOptions:
    """How fences are made.

    Attributes
    ----------
    method : str
        ``"alpha"`` (alpha shape), ``"polygon"`` (convex hull), ``"circle"`` or ``"exact"``
        (the required region itself).
    alpha_radius : float, optional
        Alpha in metres; None picks the smallest that joins each site into one piece.
    max_vertices : int
        Simplify (outward) to at most this many vertices a polygon.
    tolerance_m : float
        Simplifications adding at most this much height always run.
    warn_distance_m : float
        Width of the warning layer around keep-out fences (0: none).
    margin_m : float, optional
        Overrides every rule's margin (0 is the paper's setting).
    """

    method: str = "alpha"
    alpha_radius: float | None = None  # metres; None = automatic per site
    max_vertices: int = 32
    tolerance_m: float = 1.0
    warn_distance_m: float = 30.0
    margin_m: float | None = None  # overrides every rule's margin (0 = the paper's setting)


@dataclass
class Fence:
    """A fence around a site, in the site's metric frame.

    Attributes
    ----------
    site_id, name, category : str
        From the site.
    kind : str
        ``"keep_out"``, ``"keep_in"`` or ``"warning"``.
    method : str
        How it was made (``FenceOptions.method``).
    margin_m : float
        Least distance from the restricted area to the fence's boundary.
    alt_min_m, alt_max_m : float, optional
        The altitude band it applies to.
    sources : list of str
    frame : LocalFrame
    local : shapely.Polygon or shapely.MultiPolygon
        The fence, metres.
    circle : tuple, optional
        ``(x, y, radius)`` in metres, for a circle fence.
    alpha_m : float, optional
        The alpha used.
    repaired : bool
        The fence failed its containment check and was united with the required region.
    properties : dict
        ED-269 restriction, reasons, references and applicability, when the features had them.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.geo.frame import LocalFrame
    >>> fence = Fence("hospital/way/1", None, "hospital", "keep_out", "exact", 30.0, None, None,
    ...               ["way/1"], LocalFrame(14.5, 35.9), shapely.box(-50, -50, 50, 50))
    >>> fence.vertices, fence.area_m2
    (4, 10000.0)
    >>> round(fence.geometry.bounds[0], 6)
    14.499446
    """

    site_id: str
    name: str | None
    category: str
    kind: str  # keep_out | keep_in | warning
    method: str
    margin_m: float
    alt_min_m: float | None
    alt_max_m: float | None
    sources: list
    frame: object
    local: object  # metric Polygon / MultiPolygon
    circle: tuple | None = None  # (x, y, radius) metric, for circle fences
    alpha_m: float | None = None
    repaired: bool = False
    properties: dict = field(default_factory=dict)

    @property
    def geometry(self):
        """The fence in WGS84 (lon, lat)."""
        g = getattr(self, "_wgs84", None)
        if g is None:
            g = self.frame.geom_to_wgs84(self.local)
            self._wgs84 = g
        return g

    @property
    def vertices(self) -> int:
        """Vertices of its outer rings (1 for a circle)."""
        if self.circle is not None:
            return 1
        if type(self.local) is shapely.Polygon and not self.local.is_empty:
            return int(shapely.get_num_points(self.local.exterior)) - 1
        rings = shapely.get_exterior_ring(shapely.get_parts(self.local))
        return int(np.sum(shapely.get_num_points(rings) - 1))

    @property
    def area_m2(self) -> float:
        """Its area, square metres (a circle's true area)."""
        if self.circle is not None:
            return math.pi * self.circle[2] ** 2
        return float(self.local.area)

    @property
    def circle_wgs84(self):
        """(lon, lat, radius_m) of a circle fence, else None."""
        if self.circle is None:
            return None
        lon, lat = self.frame.to_wgs84(self.circle[0], self.circle[1])
        return float(lon), float(lat), float(self.circle[2])


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


def _simplify_parts(geom, opts, outward=True):
    polys = outer_polygons(geom)
    out = [simplify_polygon(p, opts.max_vertices, opts.tolerance_m, outward) for p in polys]
    if len(out) == 1:
        return out[0]
    return fill_holes(shapely.union_all(out))


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
    method = opts.method
    if method == "alpha":
        shape, alpha = alpha_shape(region, opts.alpha_radius)
        return _simplify_parts(shape, opts), None, alpha
    if method == "polygon":
        return _simplify_parts(shapely.convex_hull(region), opts), None, None
    if method == "circle":
        c = enclosing_circle(region)
        return circle_polygon(*c), c, None
    if method == "exact":
        return fill_holes(region), None, None
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
    return bool(shapely.distance(geometry, shapely.boundary(fence_geom)) >= margin_m - slack)


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
    base = dict(
        site_id=site.site_id,
        name=site.name,
        category=site.category,
        alt_min_m=site.alt_min_m,
        alt_max_m=site.alt_max_m,
        sources=site.sources,
        frame=site.frame,
        properties=site_properties(site),
    )
    geometry = site.geometry
    margin = site.margin_m if opts.margin_m is None else opts.margin_m
    zone = zone_circle(site, margin, PAD_M)  # one circle zone: one circle item onboard
    if site.kind == "keep_in":
        return [_keep_in(site, geometry, margin, opts, base, zone)]
    region = required_region(geometry, margin)
    method = opts.method if zone is None else "circle"
    if zone is None:
        local, circle, alpha = outer_fence(region, opts)
    else:
        local, circle, alpha = circle_polygon(*zone), zone, None
    repaired = False
    if not covers_required(local, circle, geometry, margin):
        local, circle, repaired = fill_holes(shapely.union(local, region)), None, True
    main = Fence(
        kind=site.kind,
        method=method,
        margin_m=margin,
        local=local,
        circle=circle,
        alpha_m=alpha,
        repaired=repaired,
        **base,
    )
    fences = [main]
    if site.kind == "keep_out" and opts.warn_distance_m > 0:
        fences.append(_warning_layer(main, geometry, opts, base))
    return fences


def _warning_layer(main, geometry, opts, base):
    margin = main.margin_m + opts.warn_distance_m
    if main.circle is not None:
        x, y, r = main.circle
        c = (x, y, r + opts.warn_distance_m)
        local = circle_polygon(*c)
    else:
        c = None
        if opts.method == "exact":
            grown = shapely.buffer(
                main.local, opts.warn_distance_m * circle_steps(QUAD_SEGS), quad_segs=QUAD_SEGS
            )
            local = grown
        else:
            # mitred corners contain the round offset and add no arc vertices
            grown = shapely.buffer(
                main.local, opts.warn_distance_m, join_style="mitre", mitre_limit=4.0
            )
            local = _simplify_parts(grown, opts)
    repaired = False
    if not covers_required(local, c, geometry, margin):
        local, c, repaired = (
            fill_holes(shapely.union(local, required_region(geometry, margin))),
            None,
            True,
        )
    return Fence(
        kind="warning",
        method=main.method,
        margin_m=margin,
        local=local,
        circle=c,
        alpha_m=main.alpha_m,
        repaired=repaired,
        **base,
    )


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
    return Fence(
        kind="keep_in", method=opts.method, margin_m=margin, local=local, circle=circle, **base
    )
