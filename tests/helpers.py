"""Independent checks used by the tests: a verifying metric frame that is *not* the one the
kit used (transverse Mercator instead of azimuthal equidistant, another origin); and
:func:`until`, the one way a test waits for a state no event announces."""

import asyncio
import json

import numpy as np
import pyproj
import shapely
import shapely.errors


class VerifyFrame:
    def __init__(self, lon0, lat0):
        self.t = pyproj.Transformer.from_pipeline(
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
            f"+step +proj=tmerc +lat_0={lat0!r} +lon_0={lon0!r} +k=1 +ellps=WGS84"
        )

    def local(self, geom):
        """``geom`` (lon/lat) in this frame, its edges read as straight lon/lat lines (as
        GeoJSON, QGroundControl and ArduPilot read them): each edge is cut into pieces of at
        most 2e-4 degrees (22 m) before projecting, short enough that no piece bows a
        millimetre from its chord below 87 degrees of latitude (a geometry over 1° across:
        a 5,000th of it)."""

        def f(c):
            x, y = self.t.transform(c[:, 0], c[:, 1])
            return np.column_stack([x, y])

        geom = _unwrapped(geom)
        b = shapely.bounds(geom)
        span = float(np.hypot(b[2] - b[0], b[3] - b[1])) if np.isfinite(b).all() else 0.0
        try:  # 2e-4 degrees, or a 5,000th of the geometry across (a few km: the same)
            geom = shapely.segmentize(geom, max(2e-4, span / 5000.0))
        except shapely.errors.GEOSException:  # a degenerate line (repeated points) as it is
            pass
        return shapely.transform(geom, f)

    def xy(self, lon, lat):
        return self.t.transform(lon, lat)


def _unwrapped(geom):
    """A geometry across the antimeridian with its western longitudes moved east by 360, so
    that its edges are the short ones the kit reads (the verifying frame takes any lon)."""

    def f(c):
        lon = c[:, 0]
        if lon.size and lon.max() - lon.min() > 180.0:
            c = c.copy()
            c[:, 0] = np.where(lon < 0.0, lon + 360.0, lon)
        return c

    if isinstance(geom, np.ndarray):
        return np.array([shapely.transform(g, f) for g in geom], dtype=object)
    return shapely.transform(geom, f)


def _valid_local(frame, g):
    """``g`` in ``frame``, made valid; a polygon without area (collinear vertices, a sliver)
    is the line it is, made valid first, as the kit reads it."""
    if g.geom_type in ("Polygon", "MultiPolygon") and not g.area > 0:
        g = shapely.make_valid(g)
    out = shapely.make_valid(frame.local(g))
    if out.is_empty and not g.is_empty:
        out = shapely.make_valid(frame.local(shapely.make_valid(g)))
    return out


def restricted_in(frame, geoms_wgs84, widths):
    """The restricted area (points and lines widened as the rules say), computed
    independently in ``frame``; the discs are inscribed polygons, so they lie inside the
    true discs the kit must honour."""
    local = [_valid_local(frame, g) for g in geoms_wgs84]
    parts = [shapely.buffer(g, w, quad_segs=32) if w > 0 else g for g, w in zip(local, widths)]
    return shapely.union_all(parts)


GEOS_NOISE_M = 1e-6  # a micrometre: rounding in GEOS's predicates, not a fence that fails


def missing_area(fence, restricted, margin):
    """How the fence fails to contain ``restricted`` plus ``margin``, checked exactly (no
    buffer approximation): '' if it contains it, else a description."""
    if not fence.covers(restricted):
        outside = shapely.difference(restricted, fence)
        # how far any of it lies from the fence: below GEOS_NOISE_M, GEOS's rounding (3.11
        # on collinear input leaves slivers of 1e-12 m² along the fence's edge)
        corners = shapely.points(shapely.get_coordinates(outside))
        reach = float(shapely.distance(corners, fence).max()) if len(corners) else 0.0
        if reach > GEOS_NOISE_M:
            return (
                f"{outside.area:.6f} m² of the restricted area is outside, "
                f"reaching {reach:.6f} m beyond the fence"
            )
    if margin > 0:
        d = shapely.distance(restricted, fence.boundary)
        if d < margin - 1e-6:
            return f"the restricted area comes within {d:.4f} m of the fence (margin {margin} m)"
    return ""


def geojson_fences(text):
    doc = json.loads(text)
    return [(f["properties"], shapely.geometry.shape(f["geometry"])) for f in doc["features"]]


async def until(predicate, what: str, timeout: float = 60.0, poll: float = 0.01):
    """Wait until ``predicate()`` is true, looking every ``poll`` seconds: for a state that no
    event announces (a file written, a task started, a count reached). ``predicate`` may
    raise (an AssertionError when what it watches stopped). ``timeout`` is a deadline against
    a hang, not a bound on how long it should take: past it, AssertionError saying ``what``
    did not happen."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate():
        if loop.time() > deadline:
            raise AssertionError(f"not within {timeout:g} s: {what}")
        await asyncio.sleep(poll)
