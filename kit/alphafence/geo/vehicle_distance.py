"""Distances as ArduPilot measures them, for the circles a vehicle holds.

ArduPilot decides a circle breach with ``Location::get_distance``: a flat-earth distance on a
6,378,137 m sphere, the longitude difference scaled by the cosine of the circle centre's
latitude (``LATLON_TO_M``). Near the equator that reads north-south distances up to 0.7 %
longer than the WGS84 geodesic, near the poles 0.3 % shorter, and off the centre's latitude
east-west ones differ too. A circle item therefore carries the radius that makes the vehicle's
circle contain (exclusion) or stay inside (inclusion) the geodesic circle it stands for:
:func:`vehicle_radius`.
"""

from __future__ import annotations

import math

import numpy as np
from pyproj import Geod

from alphafence.geo.coords import E7

GEOD = Geod(ellps="WGS84")
LATLON_TO_M = 6_378_137.0 * math.pi / 180.0  # ArduPilot's metres per degree (LATLON_TO_M * 1e7)
_AZIMUTHS = np.arange(0.0, 360.0, 0.5)


def vehicle_distance_m(lon, lat, clon, clat):
    """ArduPilot's ``Location::get_distance`` from positions to a circle's centre, metres.

    Positions and centre are taken at the vehicle's 1e-7 degrees first.

    Examples
    --------
    >>> round(float(vehicle_distance_m(0.0, 0.01, 0.0, 0.0)), 2)  # 0.01° of latitude
    1113.19
    """
    q = lambda v: np.rint(np.asarray(v, float) * E7) / E7  # noqa: E731
    dlat = q(clat) - q(lat)
    dlon = (q(clon) - q(lon) + 180.0) % 360.0 - 180.0
    scale = max(math.cos(math.radians(float(q(clat)))), 0.01)
    return np.hypot(dlat, dlon * scale) * LATLON_TO_M


def vehicle_radius(lon, lat, radius_m, outward=True):
    """The radius a circle item needs so that ArduPilot's circle around ``(lon, lat)``
    contains (``outward``) or lies inside the geodesic circle of ``radius_m``.

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
    n = len(_AZIMUTHS)
    plon, plat, _ = GEOD.fwd(np.full(n, float(lon)), np.full(n, float(lat)), _AZIMUTHS,
                             np.full(n, float(radius_m)))  # fmt: skip
    d = vehicle_distance_m(plon, plat, lon, lat)
    if outward:
        return float(d.max() * (1 + 1e-6) + 0.01)
    return float(max(d.min() * (1 - 1e-6) - 0.01, 0.0))
