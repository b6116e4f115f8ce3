"""A model of how ArduPilot decides a fence breach, and a containment check that owes nothing
to the kit's metric frames.

ArduPilot's ``AC_PolyFence_loader::breached`` (current master, ``libraries/AC_Fence``):

- a position inside any exclusion polygon (``Polygon_outside`` on the latitude and longitude
  integers, 1e-7 degrees, of the position and the vertices: straight lines in lat/lng, no wrap
  at the antimeridian) or exclusion circle (``Location::get_distance`` below the radius) is a
  breach;
- of the inclusion polygons and circles (outside a circle: distance above the radius), the
  position must be inside **every** one (their intersection), or with ``FENCE_OPTIONS`` bit 1
  (``INCLUSION_UNION``) inside at least one: :func:`breached`.

``Location::get_distance`` scales the longitude difference at the **mean** latitude of the two
points (``longitude_scale((lat + loc2.lat) / 2)``) and multiplies by LOCATION_SCALING_FACTOR,
0.011131884502145034 m per 1e-7 degree (a 6,378,100 m sphere). The model is written here from
ArduPilot's source (``AP_Math/polygon.cpp``, ``AP_Common/Location.cpp``) and shares no code with
the kit; ``tests/test_ardupilot_model.py`` holds it to cases written from that source and to
SITL's own FENCE_STATUS.

:func:`clearance` measures, for the zone's boundary as its file means it (straight lon/lat
edges, sampled densely), whether ArduPilot would call every sample inside a fence, and the
geodesic distance (pyproj's ``Geod`` on WGS84) from each sample to the fence's boundary read
as straight lon/lat lines.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from pyproj import Geod
from scipy.spatial import cKDTree

# MAVLink's common.xml: MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION ... _CIRCLE_EXCLUSION
POLYGON_INCLUSION, POLYGON_EXCLUSION, CIRCLE_INCLUSION, CIRCLE_EXCLUSION = 5001, 5002, 5003, 5004

GEOD = Geod(ellps="WGS84")
LATLON_TO_M = 0.011131884502145034  # ArduPilot's LOCATION_SCALING_FACTOR: m per 1e-7 degree


def e7(deg):
    """Degrees -> ArduPilot's int32 1e-7 degrees (as the kit's items carry them)."""
    return np.rint(np.asarray(deg, float) * 1e7).astype(np.int64)


def polygon_outside(lat, lon, ring_lat, ring_lon):
    """ArduPilot's ``Polygon_outside`` for many positions: True where outside.

    Every argument in degrees; all are taken to 1e-7 degree integers first, as the vehicle
    holds them. The ring is not closed. ArduPilot's points are ``Vector2l(lat, lng)``: x is the
    latitude, y the longitude; its sign shortcuts are kept as they are."""
    px, py = e7(lat), e7(lon)
    vx, vy = e7(ring_lat), e7(ring_lon)
    outside = np.ones(np.shape(px), bool)
    n = len(vx)
    for i in range(n):
        j = (i - 1) % n
        crosses = (vy[i] > py) != (vy[j] > py)
        dx1, dx2 = px - vx[i], vx[j] - vx[i]
        dy1, dy2 = py - vy[i], vy[j] - vy[i]
        m1 = np.where(dx1 < 0, -1, 1) * (-1 if dy2 < 0 else 1)
        m2 = (-1 if dx2 < 0 else 1) * np.where(dy1 < 0, -1, 1)
        if dy2 < 0:
            flip = (m1 > m2) | ((m1 == m2) & (dx1 * dy2 > dx2 * dy1))
        else:
            flip = (m1 < m2) | ((m1 == m2) & (dx1 * dy2 < dx2 * dy1))
        outside ^= crosses & flip
    return outside


def location_distance_m(lat, lon, clat, clon, mean=True):
    """ArduPilot's ``Location::get_distance`` from positions to a circle's centre (metres):
    the longitude scaled at the mean latitude (``mean=False``: at the centre's, as earlier
    firmware did). ``diff_longitude`` wraps at the antimeridian; ``(lat + loc2.lat) / 2`` is
    int32 division (towards zero); ``longitude_scale`` is at least 0.01."""
    lat_i, lon_i = e7(lat), e7(lon)
    clat_i, clon_i = e7(clat), e7(clon)
    dlat = (clat_i - lat_i).astype(float)
    dlon = clon_i - lon_i
    dlon = np.where(dlon > 1_800_000_000, dlon - 3_600_000_000, dlon)
    dlon = np.where(dlon < -1_800_000_000, dlon + 3_600_000_000, dlon)
    at = np.trunc((lat_i + clat_i) / 2) if mean else clat_i + 0 * lat_i
    scale = np.maximum(np.cos(np.radians(at * 1e-7)), 0.01)
    return np.hypot(dlat, dlon * scale) * LATLON_TO_M


def fence_shapes(items):
    """A flat list of fence items as ArduPilot's loader groups them: ``(command, ring or
    centre, radius)`` per polygon (its run of vertices) and circle; return points left out."""
    shapes, k = [], 0
    while k < len(items):
        it = items[k]
        if it.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            n = int(it.param1)
            ring = np.array([(v.lon, v.lat) for v in items[k : k + n]], float)
            shapes.append((it.command, ring, None))
            k += n
            continue
        if it.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
            shapes.append((it.command, np.array([(it.lon, it.lat)], float), float(it.param1)))
        k += 1
    return shapes


def breached(items, lon, lat, union=False):
    """``AC_PolyFence_loader::breached`` for many positions (lon, lat arrays): True where the
    vehicle holding ``items`` is in breach, its inclusions read as their intersection, or
    their union with ``union`` (``FENCE_OPTIONS`` bit 1)."""
    lon, lat = np.atleast_1d(np.asarray(lon, float)), np.atleast_1d(np.asarray(lat, float))
    excluded = np.zeros(lon.shape, bool)
    inclusions, outside = 0, np.zeros(lon.shape, int)
    for command, ring, radius in fence_shapes(list(items)):
        if radius is None:
            out = polygon_outside(lat, lon, ring[:, 1], ring[:, 0])
        else:
            d = location_distance_m(lat, lon, ring[0, 1], ring[0, 0])
            # an exclusion breaches below its radius, an inclusion above it
            out = d > radius if command == CIRCLE_INCLUSION else d >= radius
        if command in (POLYGON_EXCLUSION, CIRCLE_EXCLUSION):
            excluded |= ~out
        else:
            inclusions += 1
            outside += out
    if union:
        left = (outside == inclusions) if inclusions else np.zeros(lon.shape, bool)
    else:
        left = outside > 0
    return excluded | left


def _unwrap(lon):
    step = np.diff(lon)
    jump = np.where(step > 180.0, -360.0, np.where(step < -180.0, 360.0, 0.0))
    return lon + np.concatenate([[0.0], np.cumsum(jump)])


def boundary_samples(geom, spacing_m):
    """Points along every ring of a lon/lat geometry, edges read as straight lon/lat lines
    (the short way across the antimeridian), no two more than ``spacing_m`` apart.

    Returns (lon, lat) arrays, longitudes in [-180, 180)."""
    lons, lats = [], []
    for poly in shapely.get_parts(geom):
        if poly.geom_type == "Point":
            c = np.asarray(poly.coords)
            lons.append(c[:, 0])
            lats.append(c[:, 1])
            continue
        rings = [poly] if poly.geom_type in ("LineString", "LinearRing") else [
            poly.exterior, *poly.interiors]  # fmt: skip
        for ring in rings:
            c = np.asarray(ring.coords)[:, :2]
            lon, lat = _unwrap(c[:, 0]), c[:, 1]
            dx = (
                np.diff(lon)
                * 111_320.0
                * np.cos(np.radians(np.maximum(np.abs(lat[:-1]), np.abs(lat[1:]))))
            )
            dy = np.diff(lat) * 111_320.0
            k = np.maximum(np.ceil(np.hypot(dx, dy) / spacing_m).astype(int), 1)
            for a in range(len(k)):
                t = np.arange(k[a] + (a == len(k) - 1)) / k[a]
                lons.append(lon[a] + (lon[a + 1] - lon[a]) * t)
                lats.append(lat[a] + (lat[a + 1] - lat[a]) * t)
    lon = np.concatenate(lons) if lons else np.empty(0)
    lat = np.concatenate(lats) if lats else np.empty(0)
    return (lon + 180.0) % 360.0 - 180.0, lat


def _xyz(lon, lat):
    lo, la = np.radians(lon), np.radians(lat)
    return np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])


CHUNK = 100_000  # zone samples measured at a time: memory stays bounded for any zone


def spacing_for(margin_m):
    """The sample spacing whose slack is at most a tenth of the margin: a distance measured
    at samples ``s`` apart can dip by at most ``s / 2`` between them (distance to a set is
    1-Lipschitz), so ``s = margin / 5`` (at least 0.5 m, at most 50 m)."""
    return min(max(margin_m / 5.0, 0.5), 50.0)


def covers_as_read(rings, zone):
    """Exact: whether the polygons ``rings`` (lon/lat vertices, each taken to the vehicle's
    1e-7 degrees), read as straight lon/lat lines as ArduPilot reads them, cover the zone
    (its edges straight lon/lat lines as GeoJSON means them)."""
    parts = [shapely.Polygon(np.rint(np.asarray(r, float) * 1e7) / 1e7) for r in rings]
    parts = [shapely.make_valid(p) for p in parts]
    return bool(parts) and bool(shapely.covers(shapely.union_all(parts), zone))


def clearance(zone, rings, spacing_m=None, margin_m=0.0, reach_m=None):
    """How a zone sits in a fence made of lon/lat ``rings``, as ArduPilot reads them.

    Parameters
    ----------
    zone : shapely geometry
        Lon/lat, its edges meant as straight lon/lat lines.
    rings : list of ndarray
        Each a polygon's (n, 2) lon/lat vertices: the fence's parts (a point is inside the
        fence when it is inside any part).
    spacing_m : float, optional
        Sample spacing along the zone's boundary (default :func:`spacing_for` the margin).
    margin_m : float
    reach_m : float, optional
        Distances beyond this are not measured (inf); default twice the margin plus a
        kilometre.

    Returns
    -------
    outside : int
        Zone samples ArduPilot would call outside every part.
    distance : float
        The least geodesic distance (metres) from a zone sample to a part's boundary (inf
        when none is within reach); the parts' shared edges along the antimeridian are not
        boundary. Between samples it may be up to half the spacing less.
    each : ndarray
        That distance for every sample.
    inside : ndarray of bool
        Whether ArduPilot calls each sample inside.
    """
    if spacing_m is None:
        spacing_m = spacing_for(margin_m)
    lon, lat = boundary_samples(zone, spacing_m)
    # a zone split at the antimeridian: its cut is no boundary (and on it, every reader's
    # inside test is a tie)
    keep = np.abs(lon) < 180.0 - 2e-7
    lon, lat = lon[keep], lat[keep]
    inside = np.zeros(lon.shape, bool)
    for ring in rings:
        inside |= ~polygon_outside(lat, lon, ring[:, 1], ring[:, 0])
    # the fence's boundary, sampled along its lon/lat edges
    segs = []
    for ring in rings:
        closed = np.vstack([ring, ring[:1]])
        for a, b in zip(closed[:-1], closed[1:]):
            if abs(a[0]) == 180.0 and abs(b[0]) == 180.0:
                continue  # a cut along the antimeridian between two parts
            segs.append((a, b))
    if not segs:
        return int((~inside).sum()), math.inf, np.full(lon.shape, np.inf), inside
    a = np.array([s[0] for s in segs])
    b = np.array([s[1] for s in segs])
    b[:, 0] = a[:, 0] + (b[:, 0] - a[:, 0] + 180.0) % 360.0 - 180.0
    fine = max(spacing_m, 1.0)
    length = np.hypot((b[:, 0] - a[:, 0]) * np.cos(np.radians(np.maximum(abs(a[:, 1]),
                                                                        abs(b[:, 1])))),
                      b[:, 1] - a[:, 1]) * 111_320.0  # fmt: skip
    k = np.maximum(np.ceil(length / fine).astype(int), 1)
    seg_of = np.repeat(np.arange(len(segs)), k + 1)
    t = np.concatenate([np.arange(n + 1) / n for n in k])
    slon = a[seg_of, 0] + (b[seg_of, 0] - a[seg_of, 0]) * t
    slat = a[seg_of, 1] + (b[seg_of, 1] - a[seg_of, 1]) * t
    tree = cKDTree(_xyz(slon, slat))
    if reach_m is None:
        reach_m = 2.0 * margin_m + 2.0 * fine + 1000.0  # farther: clear enough
    best = np.full(len(lon), np.inf)
    for start in range(0, len(lon), CHUNK):
        part = slice(start, start + CHUNK)
        best[part] = _nearest_edges(lon[part], lat[part], tree, a, b, seg_of, reach_m)
    return int((~inside).sum()), float(best.min()) if len(best) else math.inf, best, inside


def _nearest_edges(lon, lat, tree, a, b, seg_of, reach_m):
    """Geodesic distance from each position to the nearest of the candidate fence segments
    (those of the four nearest fence samples within ``reach_m``), inf beyond."""
    n_samples = tree.n
    _, near = tree.query(_xyz(lon, lat), k=min(4, n_samples),
                         distance_upper_bound=reach_m / 6_371_000.0)  # fmt: skip
    near = near.reshape(len(lon), -1)
    best = np.full(len(lon), np.inf)
    for column in near.T:
        # the nearest point of each candidate segment, found in a plane tangent at the sample
        found = column < n_samples
        s = seg_of[np.where(found, column, 0)]
        cos = np.cos(np.radians(lat))
        ax = ((a[s, 0] - lon + 180.0) % 360.0 - 180.0) * cos
        bx = ax + (b[s, 0] - a[s, 0]) * cos
        ay, by = a[s, 1] - lat, b[s, 1] - lat
        dx, dy = bx - ax, by - ay
        dd = dx * dx + dy * dy
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.clip(np.where(dd > 0, -(ax * dx + ay * dy) / dd, 0.0), 0.0, 1.0)
        qlon = a[s, 0] + (b[s, 0] - a[s, 0]) * u
        qlat = a[s, 1] + (b[s, 1] - a[s, 1]) * u
        _, _, dist = GEOD.inv(lon, lat, (qlon + 180.0) % 360.0 - 180.0, qlat)
        best = np.minimum(best, np.where(found, dist, np.inf))
    return best


def excursion_m(zone, rings, margin_m, spacing_m=None, reach_m=None):
    """How far the zone plus ``margin_m`` reaches beyond the fence as ArduPilot reads it
    (0 when it holds): the margin less the least clearance, or the margin plus the least
    clearance when zone samples lie outside."""
    outside, dist, each, inside = clearance(zone, rings, spacing_m, margin_m, reach_m)
    if outside:
        return margin_m + float(each[~inside].max())
    return max(0.0, margin_m - dist)


def circle_rim(lon, lat, radius_m, n=720):
    """Positions ArduPilot measures ``radius_m`` from a circle's centre (lon, lat arrays):
    its mean-latitude distance inverted (north and east offsets in 1e-7 degrees, the east one
    scaled at the latitude halfway to the rim)."""
    ang = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    dlat = radius_m / LATLON_TO_M * np.cos(ang) * 1e-7  # degrees
    centre = float(np.rint(lat * 1e7) * 1e-7)
    scale = np.maximum(np.cos(np.radians(centre + dlat / 2.0)), 0.01)
    return lon + radius_m / LATLON_TO_M * np.sin(ang) * 1e-7 / scale, lat + dlat


def circle_inradius_m(lon, lat, radius_m):
    """The largest geodesic (WGS84) radius whose circle lies inside ArduPilot's circle of
    ``radius_m``: what an exclusion circle item surely holds."""
    rlon, rlat = circle_rim(lon, lat, radius_m)
    n = len(rlon)
    return float(GEOD.inv(np.full(n, lon), np.full(n, lat), rlon, rlat)[2].min())


def circle_outradius_m(lon, lat, radius_m):
    """The smallest geodesic radius whose circle holds ArduPilot's circle of ``radius_m``:
    what an inclusion circle item may reach."""
    rlon, rlat = circle_rim(lon, lat, radius_m)
    n = len(rlon)
    return float(GEOD.inv(np.full(n, lon), np.full(n, lat), rlon, rlat)[2].max())
