"""A model of how PX4 decides a geofence breach, written from its source
(``src/modules/navigator/geofence.cpp``) and held to PX4 SITL by ``tests/test_px4_sitl.py``.

- ``Geofence::insidePolygon``: PNPOLY on the vertices' degrees (doubles from the 1e-7 degree
  integers): an edge counts where ``(v_i.lon >= lon) != (v_j.lon >= lon)`` and ``lat <=`` the
  edge's latitude at ``lon``; straight lines in lat/lon.
- ``Geofence::insideCircle``: both points projected by ``MapProjection::project`` from a
  reference set at the first circle check (azimuthal equidistant on a sphere of
  CONSTANTS_RADIUS_OF_EARTH, 6,371,000 m), inside when ``dx² + dy² < r²``.
- ``Geofence::isInsidePolygonOrCircle``: every area must pass (inclusions intersected,
  exclusions avoided).
- ``Geofence::_updateFence``: an area whose check fails at home is discarded as it loads.
"""

from __future__ import annotations

import numpy as np

from .ardupilot_model import fence_shapes

# MAVLink's common.xml: MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, _CIRCLE_INCLUSION, _EXCLUSION
POLYGON_EXCLUSION, CIRCLE_INCLUSION, CIRCLE_EXCLUSION = 5002, 5003, 5004

EARTH_M = 6_371_000.0  # CONSTANTS_RADIUS_OF_EARTH


def project(lat, lon, ref_lat, ref_lon):
    """``MapProjection::project``: metres north (x) and east (y) of the reference."""
    la, lo = np.radians(np.asarray(lat, float)), np.radians(np.asarray(lon, float))
    rla, rlo = np.radians(ref_lat), np.radians(ref_lon)
    cos_d_lon = np.cos(lo - rlo)
    arg = np.clip(np.sin(rla) * np.sin(la) + np.cos(rla) * np.cos(la) * cos_d_lon, -1.0, 1.0)
    c = np.arccos(arg)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(np.abs(c) > 0, c / np.sin(c), 1.0)
    x = k * (np.cos(rla) * np.sin(la) - np.sin(rla) * np.cos(la) * cos_d_lon) * EARTH_M
    y = k * np.cos(la) * np.sin(lo - rlo) * EARTH_M
    return x, y


def inside_circle(lon, lat, clon, clat, radius, ref):
    """``Geofence::insideCircle`` for many positions; ``ref`` is ``(lat, lon)``."""
    x1, y1 = project(lat, lon, *ref)
    x2, y2 = project(clat, clon, *ref)
    x1, y1, x2, y2 = (np.float32(v) for v in (x1, y1, x2, y2))  # PX4 keeps them in floats
    dx, dy = x1 - x2, y1 - y2
    return dx * dx + dy * dy < np.float32(radius) * np.float32(radius)


def inside_polygon(lon, lat, ring):
    """``Geofence::insidePolygon`` (PNPOLY) for many positions; ``ring`` is (n, 2) lon/lat."""
    v = np.rint(np.asarray(ring, float) * 1e7) / 1e7
    lon, lat = np.asarray(lon, float), np.asarray(lat, float)
    c = np.zeros(lon.shape, bool)
    n = len(v)
    for i in range(n):
        j = i - 1
        (ilon, ilat), (jlon, jlat) = v[i], v[j]
        straddles = (ilon >= lon) != (jlon >= lon)
        with np.errstate(invalid="ignore", divide="ignore"):
            at = (jlat - ilat) * (lon - ilon) / (jlon - ilon) + ilat
        c ^= straddles & (lat <= at)
    return c


def area_passes(command, ring, radius, lon, lat, ref):
    """``checkPointAgainstPolygonCircle`` for one area: True where the position passes."""
    if radius is None:
        inside = inside_polygon(lon, lat, ring)
        return ~inside if command == POLYGON_EXCLUSION else inside
    inside = inside_circle(lon, lat, ring[0, 0], ring[0, 1], radius, ref)
    return ~inside if command == CIRCLE_EXCLUSION else inside


def breached(items, lon, lat, ref, home=None):
    """Whether PX4 holding ``items`` is in breach at each position (lon, lat arrays).

    ``ref`` is its projection reference ``(lat, lon)``; with ``home`` ``(lon, lat)`` the areas
    home breaches are discarded first, as PX4 discards them when the fence loads."""
    lon, lat = np.atleast_1d(np.asarray(lon, float)), np.atleast_1d(np.asarray(lat, float))
    ok = np.ones(lon.shape, bool)
    for command, ring, radius in fence_shapes(list(items)):
        if home is not None and not area_passes(command, ring, radius, *home, ref).all():
            continue  # "Geofence invalid, doesn't contain Home position": dropped
        ok &= area_passes(command, ring, radius, lon, lat, ref)
    return ~ok


def kept(items, home, ref):
    """How many areas PX4 keeps when the fence loads with home at ``(lon, lat)``."""
    return sum(
        bool(area_passes(c, ring, r, *home, ref).all()) for c, ring, r in fence_shapes(list(items))
    )


__all__ = ["CIRCLE_INCLUSION", "breached", "inside_circle", "inside_polygon", "kept", "project"]


def circle_inradius_m(lon, lat, radius_m, reach_m=100_000.0):
    """The largest geodesic (WGS84) radius whose circle PX4 reads inside its circle of
    ``radius_m`` wherever its projection reference lies within ``reach_m``: what an exclusion
    circle item surely holds (the projection lengthens a distance by c / sin c at most)."""
    from .ardupilot_model import GEOD

    az = np.arange(0.0, 360.0, 0.25)
    n = az.size
    plon, plat, _ = GEOD.fwd(np.full(n, lon), np.full(n, lat), az, np.full(n, float(radius_m)))
    la, lo = np.radians(plat), np.radians(plon)
    cla, clo = np.radians(lat), np.radians(lon)
    h = np.sin((la - cla) / 2) ** 2 + np.cos(la) * np.cos(cla) * np.sin((lo - clo) / 2) ** 2
    sphere = 2 * EARTH_M * np.arcsin(np.sqrt(h))  # great-circle distance on PX4's sphere
    c = reach_m / EARTH_M
    stretch = c / np.sin(c)
    return float(radius_m / (sphere.max() / radius_m * stretch) * (1 - 1e-6) - 0.01)
