"""KML edges as Google Earth draws them: along the geodesic (great circle) between vertices.

The kit reads a polygon's edge as the straight line between its vertices' ``(lon, lat)``, as
GeoJSON, ED-269 and ArduPilot mean it (:mod:`alphafence.geo.lonlat`). Google Earth draws
the edges of a KML polygon, and of a LinearRing or LineString with
``<tessellate>1</tessellate>``, along the geodesic between the vertices. Over a long edge
the two readings part by about ``L**2 * tan(lat) / (8 * R)``: 145 m for a 60 km edge along
the parallel at 64°N, under a centimetre for the edges of a few hundred metres most zones
have. A KML zone is therefore held under both readings:

* an edge is *read two ways* when its geodesic (pyproj's ``Geod``) and its lon/lat line lie
  more than :data:`TOLERANCE_M` (5 cm) apart (:func:`edge_departures_m`);
* the *geodesic reading* of a polygon has vertices added along the geodesic of each such edge
  (evenly spaced, the points ``Geod.npts`` gives), close enough that the lon/lat lines between
  them follow it to within 5 cm (:func:`geodesic_reading`);
* a keep-out or warning zone is the union of both readings, a keep-in zone their
  intersection (:func:`both_readings`).

A polygon whose edges are all shorter comes back as written. An edge across the antimeridian
is taken the short way, in both readings.
"""

from __future__ import annotations

import numpy as np
import pyproj
import shapely
from shapely.errors import ShapelyError

from alphafence.geo.frame import wrap_lon
from alphafence.geo.lonlat import bow_bound_length_m

GEOD = pyproj.Geod(ellps="WGS84")
TOLERANCE_M = 0.05  # an edge's readings further apart than this are both held
# bow_bound_length_m bounds how far an edge's readings part to within 3% near the poles
# (where the geodesic climbs past its ends): half the tolerance is asked of it
_SAFETY = 0.5
_SAMPLES = 15  # points along an edge where its readings are compared


def _short_way(lon1, lon2):
    """``lon2`` moved by a multiple of 360 to within 180° of ``lon1``."""
    return lon1 + (np.asarray(lon2, float) - lon1 + 180.0) % 360.0 - 180.0


def edge_departures_m(lon1, lat1, lon2, lat2):
    """How far apart (metres) the two readings of edges lie: each edge's geodesic and the
    straight line between its ends' ``(lon, lat)`` (the short way across the antimeridian).

    Measured at 15 points along each edge (a sixteenth of it apart): the distance from the
    geodesic's point (``Geod.fwd``) across the lon/lat line at the same fraction of it,
    with pyproj's geodesics (``Geod.inv``), the largest kept.

    Parameters
    ----------
    lon1, lat1, lon2, lat2 : array_like
        The edges' ends, degrees.

    Returns
    -------
    ndarray

    Examples
    --------
    >>> edge_departures_m([10.0, 10.0], [64.0, 64.0], [11.23, 10.0], [64.0, 64.5]).round(3)
    array([145.161,   0.   ])
    """
    return _departures(lon1, lat1, lon2, lat2)[0]


def _departures(lon1, lat1, lon2, lat2):
    """:func:`edge_departures_m`, and the highest latitude each geodesic reaches (of its ends
    and the points measured)."""
    lon1, lat1, lon2, lat2 = np.broadcast_arrays(
        *(np.asarray(v, float) for v in (lon1, lat1, lon2, lat2))
    )
    if not lon1.size:
        return np.zeros(lon1.shape), np.zeros(lon1.shape)
    az, _, length = GEOD.inv(lon1, lat1, lon2, lat2)
    t = (np.arange(1, _SAMPLES + 1) / (_SAMPLES + 1.0))[:, None]
    glon, glat, _ = GEOD.fwd(*np.broadcast_arrays(lon1, lat1, az, length * t))
    dlon, dlat = _short_way(lon1, lon2) - lon1, lat2 - lat1
    slon, slat = wrap_lon(lon1 + dlon * t), lat1 + dlat * t
    # the lon/lat line's heading at each point, towards a point 1/1000 of the edge further on
    nlon, nlat = wrap_lon(lon1 + dlon * (t + 1e-3)), lat1 + dlat * (t + 1e-3)
    heading = GEOD.inv(slon, slat, nlon, nlat)[0]
    bearing, _, apart = GEOD.inv(slon, slat, glon, glat)
    across = np.abs(apart * np.sin(np.radians(bearing - heading)))
    top = np.fmax(np.fmax(np.abs(lat1), np.abs(lat2)), np.abs(glat).max(axis=0))
    return np.where(length > 0, np.nan_to_num(across).max(axis=0), 0.0), top


def _two_ways(coords, tolerance_m):
    """Which edges of a closed ring ((n, 2) lon/lat) are read two ways, their geodesics'
    azimuths and lengths, and the highest latitude each reaches (where measured)."""
    lon1, lat1, lon2, lat2 = coords[:-1, 0], coords[:-1, 1], coords[1:, 0], coords[1:, 1]
    az, _, length = (np.asarray(v, float) for v in GEOD.inv(lon1, lat1, lon2, lat2))
    lat = np.fmax(np.abs(lat1), np.abs(lat2))
    maybe = np.flatnonzero(length > bow_bound_length_m(lat, _SAFETY * tolerance_m))
    two, top = np.zeros(len(length), bool), lat.copy()
    apart, top[maybe] = _departures(lon1[maybe], lat1[maybe], lon2[maybe], lat2[maybe])
    two[maybe] = apart > tolerance_m
    return two, az, length, top


def geodesic_ring(coords, tolerance_m=TOLERANCE_M):
    """A closed ring with vertices added along the geodesic of each edge read two ways.

    Parameters
    ----------
    coords : array_like, shape (n, 2)
        Lon/lat, closed (the last vertex the first).
    tolerance_m : float
        Edges whose readings lie this close are left as they are; the lon/lat lines between
        the added vertices follow the geodesic to within it.

    Returns
    -------
    ndarray or None
        The ring's new vertices (longitudes within [-180, 180]), or None when no edge is read
        two ways (or a coordinate is out of range: the reader reports it).

    Examples
    --------
    >>> ring = [(10.0, 64.0), (11.23, 64.0), (11.23, 64.05), (10.0, 64.05), (10.0, 64.0)]
    >>> len(geodesic_ring(ring))  # the two edges along the parallels, every 646 m or less
    191
    >>> geodesic_ring([(10.0, 64.0), (10.01, 64.0), (10.01, 64.01), (10.0, 64.0)]) is None
    True
    """
    coords = np.asarray(coords, float)[:, :2]
    if len(coords) < 2 or not (np.abs(coords) <= (180.0, 90.0)).all():
        return None
    two, az, length, top = _two_ways(coords, tolerance_m)
    i = np.flatnonzero(two)
    if not i.size:
        return None
    lon, lat, az, length = coords[i, 0], coords[i, 1], az[i], length[i]
    # evenly spaced points along each geodesic (those Geod.npts gives, all edges at once),
    # spaced for the highest latitude it reaches
    step = bow_bound_length_m(top[i], _SAFETY * tolerance_m)
    n = np.maximum(np.ceil(length / step) - 1, 1).astype(int)
    edge = np.repeat(np.arange(i.size), n)
    k = np.arange(edge.size) - np.repeat(np.cumsum(n) - n, n) + 1
    plon, plat, _ = GEOD.fwd(lon[edge], lat[edge], az[edge], length[edge] * k / (n[edge] + 1.0))
    pts = np.insert(coords, np.repeat(i + 1, n), np.column_stack([plon, plat]), axis=0)
    pts[:, 0] = wrap_lon(pts[:, 0])
    return pts


def geodesic_reading(geom, tolerance_m=TOLERANCE_M):
    """A polygon (or multipolygon) with every ring's edges read along their geodesics
    (:func:`geodesic_ring`); the same object when no edge is read two ways.

    Examples
    --------
    >>> strip = shapely.box(10.0, 64.0, 11.23, 64.05)
    >>> int(shapely.get_num_coordinates(geodesic_reading(strip)))
    191
    >>> small = shapely.box(10.0, 64.0, 10.01, 64.01)
    >>> geodesic_reading(small) is small
    True
    """
    if geom.geom_type == "MultiPolygon":
        parts = [geodesic_reading(p, tolerance_m) for p in geom.geoms]
        if all(p is q for p, q in zip(parts, geom.geoms)):
            return geom
        return shapely.MultiPolygon(parts)
    if geom.geom_type != "Polygon" or geom.is_empty:
        return geom
    rings = [geom.exterior, *geom.interiors]
    read = [geodesic_ring(np.asarray(r.coords), tolerance_m) for r in rings]
    if all(r is None for r in read):
        return geom
    shell, *holes = [np.asarray(r.coords) if g is None else g for r, g in zip(rings, read)]
    return shapely.Polygon(shell, holes)


def _polygonal(geom):
    parts = [p for p in shapely.get_parts(geom) if p.geom_type in ("Polygon", "MultiPolygon")]
    return shapely.union_all(parts) if parts else shapely.Polygon()


def both_readings(straight, geodesic):
    """A zone held under both readings of its edges: ``(keep_out, keep_in)``, their union
    and their intersection (lon/lat, longitudes within [-180, 180]).

    Across the antimeridian (coordinates spanning more than 180° of longitude) both are
    combined the short way. Invalid polygons are made valid first.

    Parameters
    ----------
    straight, geodesic : shapely geometry
        A zone read with straight lon/lat edges and along geodesics
        (:func:`geodesic_reading`).

    Returns
    -------
    tuple of shapely geometry
        The keep-in reading may be empty: readings that share no area.

    Examples
    --------
    >>> strip = shapely.box(10.0, 64.0, 11.23, 64.05)
    >>> out, inside = both_readings(strip, geodesic_reading(strip))
    >>> out.covers(strip), strip.covers(inside), round(inside.area / strip.area, 3)
    (True, True, 0.983)
    """
    lon = np.concatenate([shapely.get_coordinates(g)[:, 0] for g in (straight, geodesic)])
    across = lon.size > 0 and float(lon.max() - lon.min()) > 180.0

    def east(xy):
        return np.column_stack([np.where(xy[:, 0] < 0.0, xy[:, 0] + 360.0, xy[:, 0]), xy[:, 1]])

    def back(xy):
        return np.column_stack([np.where(xy[:, 0] > 180.0, xy[:, 0] - 360.0, xy[:, 0]), xy[:, 1]])

    a, b = (shapely.transform(g, east) if across else g for g in (straight, geodesic))
    a, b = (g if g.is_valid else shapely.make_valid(g) for g in (a, b))
    try:
        out, inside = shapely.union(a, b), shapely.intersection(a, b)
    except ShapelyError:  # a robustness failure of the overlay: snap to a nanometre's grid
        out = shapely.union(a, b, grid_size=1e-11)
        inside = shapely.intersection(a, b, grid_size=1e-11)
    out, inside = _polygonal(out), _polygonal(inside)
    if across:
        out, inside = shapely.transform(out, back), shapely.transform(inside, back)
    return out, inside
