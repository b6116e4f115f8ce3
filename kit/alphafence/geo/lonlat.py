"""Polygons as their readers read them: edges are straight lines in longitude and latitude.

GeoJSON (RFC 7946), QGroundControl plans, ArduPilot's fence files and ArduPilot itself (its
breach check runs on the latitude and longitude integers of the vertices) join two vertices
with the straight line between their ``(lon, lat)``. In a metric frame that line is a curve:
it bows away from the straight chord between the projected vertices by about
``L**2 * tan(lat) / (8 * R)`` (L the edge's length): a centimetre for a 700 m edge at 36°,
about 100 m for a 50 km edge at 64°. Geometry built in a metric frame is therefore

* **read in** with its long edges densified along their lon/lat lines
  (:func:`densify_lonlat`), so that the projected polygon follows the zone as its file means
  it to within ``tolerance_m``, and
* **written out** with each edge pushed away from the area it must protect by the bow of
  its lon/lat reading (:func:`alphafence.geo.hold.hold_as_read`), so that the polygon its lon/lat vertices make
  still contains (or, inward, stays inside) what the metric polygon did.

:func:`as_read` gives the polygon a ring of lon/lat vertices makes, in a metric frame, for
checks. Longitudes along an edge are taken the short way (an edge never spans more than 180°
of longitude), as the build reads zones across the antimeridian.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

EARTH_RADIUS_M = 6_371_008.8
ZONE_TOLERANCE_M = 0.05  # a zone's projected edges follow its lon/lat edges to this
READ_TOLERANCE_M = 0.01  # as_read polygons follow the lon/lat reading to this
METRES_PER_DEGREE = 111_319.49  # on the equator: the most a degree of lon/lat can span
MAX_LAT = 89.0  # bows are bounded with tan(lat); beyond this no fence is written


def bow_bound_length_m(lat_deg, tolerance_m):
    """The longest edge (metres) whose lon/lat reading bows at most ``tolerance_m`` from its
    chord in a metric frame centred within 1,000 km, at latitudes up to ``|lat_deg|``.

    The bow of a straight lon/lat edge of length ``L`` is at most
    ``L**2 * (tan|lat| + 1) / (8 R)``: ``tan|lat|`` for the parallel's curvature against
    the geodesic, 1 a generous bound for the rest (a meridian's, the frame's own).

    Examples
    --------
    >>> round(float(bow_bound_length_m(36.0, 0.05)))
    1215
    >>> round(float(bow_bound_length_m(64.0, 0.05)))
    914
    """
    lat = np.minimum(np.abs(np.asarray(lat_deg, float)), MAX_LAT)
    k = np.tan(np.radians(lat)) + 1.0
    return np.sqrt(8.0 * EARTH_RADIUS_M * tolerance_m / k)


def unwrap_lon(lon):
    """Longitudes along a path made continuous: each step taken the short way (at most 180°),
    so an edge across the antimeridian reads 179.9 -> 180.1, not 179.9 -> -179.9.

    Examples
    --------
    >>> unwrap_lon(np.array([179.9, -179.9, -179.8])).round(6).tolist()
    [179.9, 180.1, 180.2]
    """
    lon = np.asarray(lon, float)
    if lon.size < 2:
        return lon.copy()
    step = np.diff(lon)
    jump = np.where(step > 180.0, -360.0, np.where(step < -180.0, 360.0, 0.0))
    return lon + np.concatenate([[0.0], np.cumsum(jump)])


def _unwrapped(coords):
    """(n, 2) lon/lat coordinates of one geometry with negative longitudes moved east by 360
    when the geometry spans more than 180° (it crosses the antimeridian)."""
    lon = coords[:, 0]
    if lon.size and lon.max() - lon.min() > 180.0:
        coords = coords.copy()
        coords[:, 0] = np.where(lon < 0.0, lon + 360.0, lon)
    return coords


def densify_lonlat(geoms, tolerance_m=ZONE_TOLERANCE_M):
    """Geometries with vertices added along their straight lon/lat edges, so that each piece
    bows at most ``tolerance_m`` from its chord in any metric frame within 1,000 km.

    Geometries too small to hold such an edge come back as they are (the same objects). A
    geometry across the antimeridian comes back with longitudes beyond 180° where it crosses
    (the short way), which the metric frames read as they should.

    Parameters
    ----------
    geoms : array_like of shapely geometry
        Lon/lat.
    tolerance_m : float

    Returns
    -------
    ndarray of shapely geometry

    Examples
    --------
    >>> import shapely
    >>> strip = shapely.box(10.0, 64.0, 11.0, 64.01)  # 49 km along the parallel at 64°N
    >>> dense = densify_lonlat([strip])[0]
    >>> int(shapely.get_num_coordinates(strip)), int(shapely.get_num_coordinates(dense))
    (5, 249)
    >>> small = shapely.box(14.5, 35.9, 14.501, 35.901)
    >>> densify_lonlat([small])[0] is small
    True
    """
    geoms = np.asarray(geoms, dtype=object).reshape(-1)
    out = geoms.copy()
    if not len(geoms):
        return out
    b = shapely.bounds(geoms)
    with np.errstate(invalid="ignore"):
        lat = np.fmax(np.abs(b[:, 1]), np.abs(b[:, 3]))
        span = np.hypot(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]) * METRES_PER_DEGREE
    step_m = bow_bound_length_m(np.nan_to_num(lat), tolerance_m)
    need = np.flatnonzero(np.nan_to_num(span) > step_m)
    for i in need.tolist():
        geom = geoms[i]
        if b[i, 2] - b[i, 0] > 180.0:
            geom = shapely.transform(geom, _unwrapped)
        # segmentize measures in degrees: a degree spans at most METRES_PER_DEGREE metres
        # GEOS's densifier repairs an invalid polygon by buffer(0), which drops a bow-tie's
        # lobe and a spike: repaired first, keeping every point the outline draws
        out[i] = shapely.segmentize(repair_keeping_all(geom), step_m[i] / METRES_PER_DEGREE)
    return out


def repair_keeping_all(geoms):
    """Invalid polygons made valid without losing any point their outlines draw: the valid
    area (``make_valid``: both lobes of a bow-tie) and the outline's own lines, so a spike out
    to a vertex and back, or a lobe an arc draws across the outline, stays restricted (as a
    line). Valid geometries are returned as they are (vectorised).

    Examples
    --------
    >>> spike = shapely.Polygon([(0, 0), (2, 0), (2, 1), (3, 1), (2, 1), (2, 2), (0, 2)])
    >>> bool(repair_keeping_all(spike).covers(shapely.Point(3, 1)))
    True
    >>> bow = shapely.Polygon([(0, 0), (2, 2), (2, 0), (0, 2)])
    >>> round(float(shapely.area(repair_keeping_all(bow))), 6)
    2.0
    """
    array = np.asarray(geoms, dtype=object)
    one = array.ndim == 0
    array = array.reshape(-1).copy()
    bad = np.flatnonzero(~shapely.is_valid(array))
    if bad.size:
        valid = shapely.make_valid(array[bad])
        # the outline's lines beyond the valid area (beyond rounding: a billionth of the
        # geometry's extent): a spike, the part of a collapsed ring
        b = shapely.bounds(array[bad])
        tiny = 1e-9 * np.fmax(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1])
        beyond = shapely.difference(shapely.boundary(array[bad]), shapely.buffer(valid, tiny))
        keep = ~shapely.is_empty(beyond)
        array[bad] = np.where(keep, shapely.union(valid, beyond), valid)
    return array[0] if one else array


def _edge_samples(frame, lon, lat, samples):
    """Metric positions of ``samples`` points inside each edge ``i -> i + 1`` of a closed
    lon/lat ring (``lon``, ``lat`` unwrapped, not closed): (n, samples, 2)."""
    t = np.arange(1, samples + 1) / (samples + 1.0)
    lon1, lat1 = np.roll(lon, -1), np.roll(lat, -1)
    if lon.size:
        lon1[-1] = lon[-1] + (lon[0] - lon[-1] + 180.0) % 360.0 - 180.0  # the short way
    slon = lon[:, None] + (lon1 - lon)[:, None] * t
    slat = lat[:, None] + (lat1 - lat)[:, None] * t
    x, y = frame.to_local(slon.ravel(), slat.ravel())
    return np.stack([np.asarray(x), np.asarray(y)], axis=-1).reshape(len(lon), samples, 2)


def _ring_lonlat(frame, pts):
    lon, lat = frame.to_wgs84(pts[:, 0], pts[:, 1])
    return unwrap_lon(np.asarray(lon, float)), np.asarray(lat, float)


def left_bows(frame, pts, samples=15):
    """How far each edge of a metric ring bows to its left when read as a straight lon/lat
    line: the largest distance (metres, 0 if none) of its lon/lat reading left of the chord.

    Parameters
    ----------
    frame : LocalFrame
    pts : ndarray, shape (n, 2)
        The ring's vertices in ``frame`` (not closed).
    samples : int
        Points measured inside each edge.

    Returns
    -------
    ndarray, shape (n,)
        Edge ``i`` runs from vertex ``i`` to vertex ``i + 1``.

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(10.5, 64.0)
    >>> x, y = frame.to_local(np.array([10.0, 11.0]), np.array([64.0, 64.0]))
    >>> square = np.array([[x[0], y[0] - 1000], [x[1], y[1] - 1000], [x[1], y[1]], [x[0], y[0]]])
    >>> left_bows(frame, square).round(1).tolist()  # the north edge, westward: bows south
    [0.0, 0.0, 95.9, 0.0]
    """
    lon, lat = _ring_lonlat(frame, pts)
    s = _edge_samples(frame, lon, lat, samples)
    a = pts
    d = np.roll(pts, -1, axis=0) - a
    length = np.hypot(d[:, 0], d[:, 1])
    rel = s - a[:, None, :]
    cross = d[:, None, 0] * rel[..., 1] - d[:, None, 1] * rel[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        left = np.where(length[:, None] > 0, cross / length[:, None], 0.0)
    return np.maximum(np.nan_to_num(left.max(axis=1)), 0.0)


def as_read(geom_lonlat, frame, tolerance_m=READ_TOLERANCE_M):
    """The polygon that lon/lat vertices make when their edges are straight lon/lat lines,
    in ``frame``'s metres, to within ``tolerance_m`` (each edge densified along its lon/lat
    line before projecting).

    Parameters
    ----------
    geom_lonlat : shapely geometry
    frame : LocalFrame
    tolerance_m : float

    Returns
    -------
    shapely geometry

    Examples
    --------
    >>> import shapely
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(10.5, 64.0)
    >>> box = shapely.box(10.0, 63.99, 11.0, 64.0)
    >>> int(shapely.get_num_coordinates(as_read(box, frame)))
    553
    """
    dense = densify_lonlat([geom_lonlat], tolerance_m)[0]
    return frame.geom_to_local(dense)


def bow_free(local, frame, tolerance_m=READ_TOLERANCE_M):
    """Whether no edge of ``local`` (metric geometries in ``frame``) can bow more than
    ``tolerance_m`` when read in lon/lat: every edge shorter than the bound at the
    geometry's latitude. Cheap: a geometry whose bounds' diagonal is under the bound needs
    nothing more; the others are measured edge by edge (no projection either way).

    Returns
    -------
    ndarray of bool

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(14.5, 35.9)  # the bound there: 543 m
    >>> bottom = [(x, 0.0) for x in range(0, 3001, 300)]
    >>> top = [(x, 300.0) for x in range(3000, -1, -300)]
    >>> dotted = shapely.Polygon(bottom + top)  # 3 km long, its edges 300 m
    >>> bow_free([dotted, shapely.box(0, 0, 3000, 300)], frame).tolist()
    [True, False]
    """
    local = np.asarray(local, dtype=object).reshape(-1)
    b = shapely.bounds(local)
    reach = np.fmax(np.fmax(np.abs(b[:, 0]), np.abs(b[:, 1])),
                    np.fmax(np.abs(b[:, 2]), np.abs(b[:, 3])))  # fmt: skip
    bound = bow_bound_length_m(np.abs(frame.lat0) + reach / METRES_PER_DEGREE, tolerance_m)
    free = ~(np.hypot(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]) > bound)  # NaN (empty): free
    todo = np.flatnonzero(~free)
    if todo.size:  # edge by edge (a ring's closing step to the next ring counts too: longer)
        coords, which = shapely.get_coordinates(local[todo], return_index=True)
        step = np.hypot(*np.diff(coords, axis=0).T)
        same = which[1:] == which[:-1]
        longest = np.zeros(todo.size)
        np.maximum.at(longest, which[1:][same], step[same])
        free[todo] = ~(longest > bound[todo])
    return free


def bow_free_one(geom, frame, tolerance_m=READ_TOLERANCE_M) -> bool:
    """:func:`bow_free` of one geometry, without array work for most (the build asks it of
    every fence, one at a time)."""
    x0, y0, x1, y1 = geom.bounds
    reach = max(abs(x0), abs(y0), abs(x1), abs(y1))
    lat = min(abs(frame.lat0) + reach / METRES_PER_DEGREE, MAX_LAT)
    bound = math.sqrt(8.0 * EARTH_RADIUS_M * tolerance_m / (math.tan(math.radians(lat)) + 1.0))
    if not math.hypot(x1 - x0, y1 - y0) > bound:  # NaN (empty): free
        return True
    return bool(bow_free([geom], frame, tolerance_m)[0])


def frame_scale(reach_m):
    """The largest scale of an azimuthal equidistant frame within ``reach_m`` of its origin:
    distances across the radius read ``(d/R) / sin(d/R)`` times too long, so a margin drawn
    there must be that much wider to hold on the ground.

    Examples
    --------
    >>> round(frame_scale(20_000.0) - 1, 9), round(frame_scale(700_000.0), 5)
    (1.642e-06, 1.00201)
    """
    a = min(float(reach_m), 0.5 * math.pi * EARTH_RADIUS_M) / EARTH_RADIUS_M
    return 1.0 if a < 1e-9 else a / math.sin(a)
