"""The circle radii the kit writes (``alphafence.geo.vehicle_distance``), computed again here
from their definitions with the tests' own models: the geodesic circle at 720 azimuths
(pyproj), measured as every ArduPilot reading measures (the model's ``Location::get_distance``,
mean or centre latitude, 6,378,100 m or 6,378,137 m spheres) or on PX4's sphere (haversine,
6,371,000 m) stretched by PX4's projection at 100 km; outward the most widened by a millionth
and a centimetre, inward the least narrowed by as much. Pinned to a part in 1e9, so a margin
dropped or a reading missed is seen, and each kit function dispatches as it says."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.geo import vehicle_distance as kit

from .ardupilot_model import GEOD, LATLON_TO_M, location_distance_m, polygon_outside

LEGACY = 0.01113195 / 0.011131884502145034  # earlier firmware's constant against today's
PX4_EARTH_M = 6_371_000.0


def rim(lon, lat, radius):
    az = np.arange(0.0, 360.0, 0.5)
    n = az.size
    rlon, rlat, _ = GEOD.fwd(np.full(n, lon), np.full(n, lat), az, np.full(n, radius))
    return rlon, rlat


def ardupilot_readings(lon, lat, radius):
    rlon, rlat = rim(lon, lat, radius)
    d = [location_distance_m(rlat, rlon, lat, lon, mean=m) for m in (True, False)]
    return np.concatenate([*d, *(x * LEGACY for x in d)])


def px4_readings(lon, lat, radius):
    rlon, rlat = rim(lon, lat, radius)
    la, lo, cla, clo = map(np.radians, (rlat, rlon, lat, lon))
    h = np.sin((la - cla) / 2) ** 2 + np.cos(la) * np.cos(cla) * np.sin((lo - clo) / 2) ** 2
    return 2 * PX4_EARTH_M * np.arcsin(np.sqrt(h))


def held(d, outward, stretch=1.0):
    if outward:
        return d.max() * stretch * (1 + 1e-6) + 0.01
    return max(d.min() * (1 - 1e-6) - 0.01, 0.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(-179.0, 179.0), st.floats(-80.0, 80.0), st.floats(0.5, 200_000.0), st.booleans())
def test_circle_radii_are_their_definition(lon, lat, radius, outward):
    c = 100_000.0 / PX4_EARTH_M
    want_ap = held(ardupilot_readings(lon, lat, radius), outward)
    want_px4 = held(px4_readings(lon, lat, radius), outward, c / math.sin(c) if outward else 1.0)
    assert kit.vehicle_radius(lon, lat, radius, outward) == pytest.approx(want_ap, rel=1e-9)
    assert kit.px4_radius(lon, lat, radius, outward) == pytest.approx(want_px4, rel=1e-9)
    assert kit.circle_radius("ardupilot", lon, lat, radius, outward) == pytest.approx(
        want_ap, rel=1e-9
    )
    assert kit.circle_radius("px4", lon, lat, radius, outward) == pytest.approx(want_px4, rel=1e-9)


def test_no_radius_is_no_radius():
    for f in (kit.vehicle_radius, kit.px4_radius):
        assert f(14.5, 35.9, 0.0) == 0.0 and f(14.5, 35.9, -1.0) == -1.0
    # a radius under a metre is still measured (widened outward, narrowed inward)
    assert kit.px4_radius(14.5, 35.9, 0.5) > 0.5 > kit.px4_radius(14.5, 35.9, 0.5, outward=False)


@settings(max_examples=60, deadline=None)
@given(st.floats(-179.0, 179.0), st.floats(-80.0, 80.0), st.floats(1.0, 100_000.0),
       st.integers(3, 90))  # fmt: skip
def test_the_rim_is_at_the_radius_by_ardupilots_distance_all_round(lon, lat, radius, n):
    rlon, rlat = kit.vehicle_circle_rim(lon, lat, radius, n=n)
    assert rlon.shape == (n,)
    d = location_distance_m(rlat, rlon, lat, lon)
    assert np.abs(d - radius).max() < 0.02 + radius * 1e-9
    # at the n bearings 0, 360/n, ... from north, in order
    north = (rlat - lat) * 1e7 * LATLON_TO_M
    east = (rlon - lon) * 1e7 * LATLON_TO_M * np.cos(np.radians(lat + (rlat - lat) / 2))
    bearing = np.degrees(np.arctan2(east, north)) % 360.0
    want = np.arange(n) * 360.0 / n
    err = (bearing - want + 180.0) % 360.0 - 180.0
    assert np.abs(err).max() < 0.5 + 5.0 / max(radius, 1.0)
    assert len(kit.vehicle_circle_rim(lon, lat, radius)[0]) == 64  # the documented default


def test_points_on_an_edge_are_read_as_ardupilot_reads_them():
    # positions exactly on the lat/lng line of an edge, in 1e-7 degree integers: ArduPilot's
    # strict comparisons decide, and the kit must decide the same
    ring_lon = np.array([0.0, 0.0004, 0.0004, 0.0])
    ring_lat = np.array([0.0, 0.0002, 0.0006, 0.0004])
    t = np.arange(0, 2001)
    on_lon = np.concatenate([t * 2e-7, 0.0004 - t * 2e-7])
    on_lat = np.concatenate([t * 1e-7, 0.0006 - t * 1e-7])
    kit_out = kit.polygon_outside(on_lon, on_lat, ring_lon, ring_lat)
    model_out = polygon_outside(on_lat, on_lon, ring_lat, ring_lon)
    assert kit_out.tolist() == model_out.tolist()
    assert kit_out.any() and not kit_out.all()  # the edges' points fall both ways


def test_a_circle_radius_is_outward_unless_asked():
    for f in (kit.vehicle_radius, kit.px4_radius):
        assert f(14.5, 35.9, 1540.0) == f(14.5, 35.9, 1540.0, True) > 1540.0
    assert kit.circle_radius("ardupilot", 14.5, 35.9, 1540.0) == kit.vehicle_radius(
        14.5, 35.9, 1540.0
    )
