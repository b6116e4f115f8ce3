"""Distances and polygons as ArduPilot (and PX4) read them, for the fence items a vehicle holds.

ArduPilot decides a circle breach with ``Location::get_distance`` (``AP_Common/Location.cpp``):
a flat-earth distance on its integer 1e-7 degrees, the longitude difference scaled by the
cosine of the **mean** latitude of the two points (``longitude_scale((lat + loc2.lat) / 2)``,
an integer division), times ``LOCATION_SCALING_FACTOR`` (0.011131884502145034 m per 1e-7
degree: a 6,378,100 m sphere). Older firmware scaled at the circle centre's latitude, and
some builds used 0.01113195 (6,378,137 m). Near the equator the distance reads north-south
up to 0.7 % longer than the WGS84 geodesic, near the poles 0.3 % shorter. A circle item
therefore carries the radius that makes the vehicle's circle contain (exclusion) or stay
inside (inclusion) the geodesic circle it stands for under **every** one of these readings:
:func:`vehicle_radius`.

A polygon is tested with ``Polygon_outside`` on the integers of the position and of the
vertices: edges straight in lat/lng, no wrap at the antimeridian (:func:`polygon_outside`).

PX4 reads a polygon's edges as straight lat/lon lines too (its PNPOLY test on the vertices'
degrees), and a circle through its own projection: :func:`px4_radius`.
"""

from __future__ import annotations

import math

import numpy as np
from pyproj import Geod

from alphafence.geo.coords import E7

GEOD = Geod(ellps="WGS84")
LATLON_TO_M = 0.011131884502145034 * E7  # ArduPilot's metres per degree (6,378,100 m sphere)
LEGACY_LATLON_TO_M = 0.01113195 * E7  # earlier firmware's (about 6,378,137 m)
_AZIMUTHS = np.arange(0.0, 360.0, 0.5)


def _e7(deg):
    return np.rint(np.asarray(deg, float) * E7)


def vehicle_distance_m(lon, lat, clon, clat, mean=True, latlon_to_m=LATLON_TO_M):
    """ArduPilot's ``Location::get_distance`` from positions to a circle's centre, metres.

    Positions and centre are taken at the vehicle's 1e-7 degrees first.

    Parameters
    ----------
    lon, lat : float or array
        Positions, degrees.
    clon, clat : float
        The centre, degrees.
    mean : bool
        Scale longitude at the mean latitude of the two points (current ArduPilot), or at
        the centre's (earlier firmware).
    latlon_to_m : float
        Metres per degree (:data:`LATLON_TO_M`, or :data:`LEGACY_LATLON_TO_M`).

    Examples
    --------
    >>> round(float(vehicle_distance_m(0.0, 0.01, 0.0, 0.0)), 2)  # 0.01° of latitude
    1113.19
    """
    lat_i, clat_i = _e7(lat), _e7(clat)
    dlat = clat_i - lat_i
    dlon = (_e7(clon) - _e7(lon) + 1.8e9) % 3.6e9 - 1.8e9
    at = np.trunc((lat_i + clat_i) / 2.0) if mean else clat_i + 0.0 * lat_i
    scale = np.maximum(np.cos(np.radians(at / E7)), 0.01)
    return np.hypot(dlat, dlon * scale) * (latlon_to_m / E7)


def vehicle_distances(lon, lat, clon, clat):
    """:func:`vehicle_distance_m` under each reading ArduPilot has had (mean or centre
    latitude, either constant), as rows of an array."""
    return np.array([
        vehicle_distance_m(lon, lat, clon, clat, mean, k)
        for mean in (True, False)
        for k in (LATLON_TO_M, LEGACY_LATLON_TO_M)
    ])  # fmt: skip


def vehicle_radius(lon, lat, radius_m, outward=True):
    """The radius a circle item needs so that ArduPilot's circle around ``(lon, lat)``
    contains (``outward``) or lies inside the geodesic circle of ``radius_m``, whichever way
    the firmware reads distance (:func:`vehicle_distances`).

    The geodesic circle is drawn at 720 azimuths and measured as the vehicle measures;
    the largest (outward) or smallest distance is taken, widened or narrowed by a
    millionth and a centimetre for what lies between the azimuths and for rounding.

    Parameters
    ----------
    lon, lat : float
        The centre, degrees.
    radius_m : float
        The geodesic radius, metres.
    outward : bool

    Returns
    -------
    float

    Examples
    --------
    >>> round(vehicle_radius(0.0, 0.0, 1540.0) - 1540.0, 1)  # at the equator: 0.7 % more
    10.4
    >>> round(vehicle_radius(14.5, 35.9, 1540.0) - 1540.0, 1)
    5.0
    >>> round(1540.0 - vehicle_radius(14.5, 35.9, 1540.0, outward=False), 1)
    1.8
    """
    if not radius_m > 0:
        return float(radius_m)
    return _held(vehicle_distances(*geodesic_rim(lon, lat, radius_m), lon, lat), outward)


def geodesic_rim(lon, lat, radius_m):
    """The geodesic (WGS84) circle of ``radius_m`` around ``(lon, lat)`` at 720 azimuths:
    ``(lon, lat)`` arrays."""
    n = len(_AZIMUTHS)
    plon, plat, _ = GEOD.fwd(np.full(n, float(lon)), np.full(n, float(lat)), _AZIMUTHS,
                             np.full(n, float(radius_m)))  # fmt: skip
    return plon, plat


def _held(d, outward, stretch=1.0):
    """The radius holding (outward) or held by distances ``d`` measured at the rim: widened
    or narrowed by a millionth and a centimetre for what lies between the azimuths."""
    if outward:
        return float(d.max() * stretch * (1 + 1e-6) + 0.01)
    return float(max(d.min() * (1 - 1e-6) - 0.01, 0.0))


def vehicle_circle_rim(lon, lat, radius_m, n=64):
    """Positions (lon, lat arrays) at ArduPilot's distance ``radius_m`` from a circle's
    centre, at ``n`` bearings: its mean-latitude distance inverted (the latitude step fixes
    the mean latitude, which scales the longitude step).

    Examples
    --------
    >>> lo, la = vehicle_circle_rim(14.5, 35.9, 1000.0, n=8)
    >>> bool(np.allclose(vehicle_distance_m(lo, la, 14.5, 35.9), 1000.0, atol=0.02))
    True
    """
    ang = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    dlat = radius_m / LATLON_TO_M * np.cos(ang)
    clat = float(np.round(lat * E7) / E7)
    # the point's mean latitude with the centre is clat + dlat / 2 whatever its longitude:
    # one step is exact but for the integer rounding
    scale = np.maximum(np.cos(np.radians(clat + dlat / 2.0)), 0.01)
    return lon + radius_m / LATLON_TO_M * np.sin(ang) / scale, lat + dlat


def polygon_outside(lon, lat, ring_lon, ring_lat):
    """ArduPilot's ``Polygon_outside`` for many positions: True where outside.

    Every argument in degrees; all are taken to 1e-7 degree integers first, as the vehicle
    holds them; the ring is not closed. The crossing rule is ArduPilot's (``AP_Math/
    polygon.cpp``): an edge counts where it straddles the position's longitude, compared
    with 64-bit products.

    Examples
    --------
    >>> sq_lon, sq_lat = [0.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0]
    >>> polygon_outside(np.array([0.5, 1.5]), np.array([0.5, 0.5]), sq_lon, sq_lat).tolist()
    [False, True]
    """
    px, py = _e7(lat).astype(np.int64), _e7(lon).astype(np.int64)
    vx, vy = _e7(ring_lat).astype(np.int64), _e7(ring_lon).astype(np.int64)
    outside = np.ones(np.shape(px), bool)
    n = len(vx)
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        crosses = (vy[i] > py) != (vy[j] > py)
        if not np.any(crosses):
            continue
        dx1, dx2 = px - vx[i], vx[j] - vx[i]
        dy1, dy2 = py - vy[i], vy[j] - vy[i]
        if dy2 < 0:
            flip = dx1 * dy2 > dx2 * dy1
        else:
            flip = dx1 * dy2 < dx2 * dy1
        outside ^= crosses & flip
    return outside


# -- PX4 ----------------------------------------------------------------------------------
# PX4's circle test (``Geofence::insideCircle``, navigator/geofence.cpp): both points projected
# by its MapProjection (azimuthal equidistant on a sphere of CONSTANTS_RADIUS_OF_EARTH, from a
# reference set where the vehicle was at the first circle check), then a plane distance. The
# projection's scale is 1 along its radii and c / sin(c) across them (c: the angle from the
# reference), never below 1: the plane distance is at least the great-circle distance on that
# sphere, and at most that times c / sin(c) for points within c of the reference.
PX4_EARTH_M = 6_371_000.0
PX4_REACH_M = 100_000.0
"""How far from PX4's projection reference (where the vehicle was when it first checked a
circle, near home) the radii :func:`px4_radius` gives hold: 100 km."""


def px4_stretch(reach_m: float = PX4_REACH_M) -> float:
    """The most PX4's projection lengthens a distance within ``reach_m`` of its reference
    (``c / sin c``).

    Examples
    --------
    >>> round((px4_stretch() - 1) * 1e6, 1)  # parts per million at 100 km
    41.1
    """
    c = reach_m / PX4_EARTH_M
    return c / math.sin(c) if c > 0 else 1.0


def great_circle_m(lon, lat, clon, clat, radius_m=PX4_EARTH_M):
    """Great-circle distance on a sphere of ``radius_m`` (haversine), metres.

    Examples
    --------
    >>> round(float(great_circle_m(0.0, 0.01, 0.0, 0.0)), 2)
    1111.95
    """
    lo, la = np.radians(np.asarray(lon, float)), np.radians(np.asarray(lat, float))
    clo, cla = math.radians(clon), math.radians(clat)
    h = np.sin((la - cla) / 2) ** 2 + np.cos(la) * math.cos(cla) * np.sin((lo - clo) / 2) ** 2
    return 2 * radius_m * np.arcsin(np.sqrt(np.clip(h, 0.0, 1.0)))


def px4_radius(lon, lat, radius_m, outward=True, reach_m=PX4_REACH_M):
    """The radius a circle item needs so that PX4's circle around ``(lon, lat)`` contains
    (``outward``) or lies inside the geodesic (WGS84) circle of ``radius_m``, wherever PX4's
    projection reference lies within ``reach_m``.

    The geodesic circle is drawn at 720 azimuths and measured on PX4's sphere; outward, the
    largest distance is lengthened by the projection's most (:func:`px4_stretch`); inward the
    least is kept (the projection only lengthens); each widened or narrowed by a millionth and
    a centimetre, as :func:`vehicle_radius` does.

    Examples
    --------
    >>> round(px4_radius(0.0, 0.0, 1540.0) - 1540.0, 1)  # at the equator: the sphere reads long
    8.7
    >>> round(1540.0 - px4_radius(0.0, 60.0, 1540.0, outward=False), 1)  # at 60°: short
    5.6
    """
    if not radius_m > 0:
        return float(radius_m)
    d = great_circle_m(*geodesic_rim(lon, lat, radius_m), lon, lat)
    return _held(d, outward, px4_stretch(reach_m))


def circle_radius(autopilot, lon, lat, radius_m, outward=True):
    """:func:`vehicle_radius` (ArduPilot) or :func:`px4_radius` (``autopilot == "px4"``)."""
    if autopilot == "px4":
        return px4_radius(lon, lat, radius_m, outward)
    return vehicle_radius(lon, lat, radius_m, outward)
