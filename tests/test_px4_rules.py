"""Fences compiled for PX4 hold as PX4 reads them (``tests/px4_model.py``), and what PX4
would not read as meant is refused before anything is sent."""

import json
import math

import numpy as np
import pytest
import shapely
import shapely.affinity
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.geo.vehicle_distance import PX4_REACH_M, px4_radius
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences
from alphafence.onboard.rules import areas_breached_at, check_for_autopilot

from . import px4_model
from .ardupilot_model import GEOD, boundary_samples


def _ring(frame, cx, cy, radius, n, wobble):
    ang = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    rad = radius * (1.0 + wobble * np.sin(3 * ang))
    return frame.geom_to_wgs84(shapely.Polygon(np.column_stack([cx + rad * np.cos(ang),
                                                                cy + rad * np.sin(ang)])))  # fmt: skip


@st.composite
def scenes(draw):
    lon0 = draw(st.floats(-179.0, 179.0))
    lat0 = draw(st.floats(-75.0, 75.0))
    frame = LocalFrame(lon0, lat0)
    records = []
    for k in range(draw(st.integers(1, 8))):
        cx, cy = draw(st.floats(-3000, 3000)), draw(st.floats(-3000, 3000))
        radius = draw(st.floats(30.0, 1500.0))
        n = draw(st.integers(5, 48))
        wobble = draw(st.floats(0.0, 0.3))
        records.append(
            FenceRecord(f"test/{k}", "keep_out", _ring(frame, cx, cy, radius, n, wobble))
        )
    # PX4's projection reference: where the vehicle first checked a circle, within its reach
    az, dist = draw(st.floats(0.0, 360.0)), draw(st.floats(0.0, PX4_REACH_M - 5000.0))
    rlon, rlat, _ = GEOD.fwd(lon0, lat0, az, dist)
    return lon0, lat0, records, (rlat, rlon), draw(st.sampled_from([6, 16, 64]))


def _zone_points(records):
    lons, lats = [], []
    for rec in records:
        lon, lat = boundary_samples(rec.geometry, 5.0)
        lons.append(lon)
        lats.append(lat)
    return np.concatenate(lons), np.concatenate(lats)


def _compile(lon0, lat0, records, max_items, keep_in=None):
    area = LocalFrame(lon0, lat0).geom_to_wgs84(shapely.box(-500, -500, 500, 500))
    return compile_fences(records, area, PROFILES["px4"], distance_m=1e6, keep_in_m=keep_in,
                          max_items=max_items)  # fmt: skip


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_every_zone_point_is_a_breach_as_px4_reads_the_compiled_fence(scene):
    lon0, lat0, records, ref, max_items = scene
    try:
        result = _compile(lon0, lat0, records, max_items)
    except InputError as err:
        assert "do not fit" in str(err)
        return
    items = result.items
    assert len(items) <= min(max_items, 64)
    assert not any(i.command == RETURN_POINT for i in items)
    lon, lat = _zone_points(records)
    inside = px4_model.breached(items, lon, lat, ref)
    assert inside.all(), f"{int((~inside).sum())} zone points PX4 reads as clear"


def _one_circle_zone(lat0):
    frame = LocalFrame(10.0, lat0)
    zone = _ring(frame, 0.0, 0.0, 1000.0, 72, 0.0)
    return [FenceRecord("test/round", "keep_out", zone)]


def test_the_geodesic_radius_is_not_enough_for_px4_at_the_equator(monkeypatch):
    # broken case: the circle item given the zone's own (geodesic) radius; PX4's sphere reads
    # north-south distances 0.6 % long near the equator, so the rim reads outside its circle
    records = _one_circle_zone(0.0)
    good = _compile(10.0, 0.0, records, 2)
    assert [i.command for i in good.items] == [CIRCLE_EXCLUSION]
    lon, lat = _zone_points(records)
    ref = (0.0, 10.0)
    assert px4_model.breached(good.items, lon, lat, ref).all()
    monkeypatch.setattr("alphafence.onboard.emit.circle_radius", lambda _a, _lo, _la, r: r)
    bad = _compile(10.0, 0.0, records, 2)
    assert bad.items[0].param1 < good.items[0].param1 - 5.0
    assert not px4_model.breached(bad.items, lon, lat, ref).all()


def test_the_projection_allowance_is_what_a_far_reference_needs():
    # PX4's circle, radius from px4_radius, seen from a reference 99 km away: the rim of the
    # geodesic circle still reads inside; without the stretch it would not (seen from the east,
    # the projection lengthens the north-south distances, the longest on PX4's sphere at 60°)
    lon, lat, r = 10.0, 60.0, 2000.0
    az = np.arange(0.0, 360.0, 1.0)
    plon, plat, _ = GEOD.fwd(np.full(az.size, lon), np.full(az.size, lat), az, np.full(az.size, r))
    for ref_az in (0.0, 90.0, 180.0, 270.0):
        rlon, rlat, _ = GEOD.fwd(lon, lat, ref_az, 99_000.0)
        radius = px4_radius(lon, lat, r)
        assert px4_model.inside_circle(plon, plat, lon, lat, radius, (rlat, rlon)).all()
    plain = px4_radius(lon, lat, r, reach_m=0.0)
    rlon, rlat, _ = GEOD.fwd(lon, lat, 90.0, 99_000.0)
    assert not px4_model.inside_circle(plon, plat, lon, lat, plain, (rlat, rlon)).all()


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-0.004, 0.004), st.floats(-0.004, 0.004), st.floats(0.0, 360.0),
    st.floats(0.0, 90_000.0),
)  # fmt: skip
def test_a_home_the_kit_accepts_keeps_every_area_as_px4_loads_it(dlon, dlat, ref_az, ref_d):
    lon0, lat0 = 14.5, 35.9
    keep_in = [FenceItem(POLYGON_INCLUSION, 4.0, lon0 + x, lat0 + y)
               for x, y in ((-0.003, -0.003), (0.003, -0.003), (0.003, 0.003), (-0.003, 0.003))]  # fmt: skip
    keep_out = [FenceItem(CIRCLE_EXCLUSION, 150.0, lon0 + 0.001, lat0),
                FenceItem(CIRCLE_INCLUSION, 600.0, lon0, lat0)]  # fmt: skip
    items = keep_in + keep_out
    home = (lon0 + dlon, lat0 + dlat)
    rlon, rlat, _ = GEOD.fwd(*home, ref_az, ref_d)
    if not areas_breached_at(items, *home):
        assert px4_model.kept(items, home, (rlat, rlon)) == 3


def test_areas_breached_at_names_what_px4_drops():
    lon0, lat0 = 14.5, 35.9
    square = [FenceItem(POLYGON_INCLUSION, 4.0, lon0 + x, lat0 + y)
              for x, y in ((-0.001, -0.001), (0.001, -0.001), (0.001, 0.001), (-0.001, 0.001))]  # fmt: skip
    out = FenceItem(CIRCLE_EXCLUSION, 30.0, lon0 + 0.0005, lat0)  # 45 m east of home
    assert areas_breached_at([*square, out], lon0, lat0) == []
    names = [a.name for a in areas_breached_at([*square, out], lon0 + 0.0005, lat0)]
    assert names == ["onboard exclusion circle 1 (item 4)"]
    names = [a.name for a in areas_breached_at([*square, out], lon0 + 0.002, lat0)]
    assert names == ["onboard inclusion polygon 1 (items 0-3)"]
    ref = (lat0, lon0)
    assert px4_model.kept([*square, out], (lon0 + 0.002, lat0), ref) == 1  # as PX4 loads it


def test_px4_refuses_two_keep_ins_and_a_return_point():
    lon0, lat0 = 14.5, 35.9
    frame = LocalFrame(lon0, lat0)
    keep_in = FenceRecord(
        "test/in", "keep_in", frame.geom_to_wgs84(shapely.box(-3000, -3000, 3000, 3000))
    )
    with pytest.raises(InputError, match="2 inclusion areas: PX4 reads them as their intersection"):
        _compile(lon0, lat0, [keep_in], 64, keep_in=200.0)
    one = _compile(lon0, lat0, [keep_in], 64)
    assert [i.command for i in one.items].count(POLYGON_INCLUSION) == len(one.items)
    area = frame.geom_to_wgs84(shapely.box(-500, -500, 500, 500))
    with pytest.raises(InputError, match="PX4 keeps none"):
        compile_fences([keep_in], area, PROFILES["px4"], return_point=(lon0, lat0))
    two = [FenceItem(CIRCLE_INCLUSION, 50.0, 0, 0), FenceItem(CIRCLE_INCLUSION, 50.0, 1, 1)]
    check_for_autopilot(two, "ardupilot")  # ArduPilot reads them as their union, with the bit
    with pytest.raises(InputError, match="f.plan: 2 inclusion areas"):
        check_for_autopilot(two, "px4", "f.plan")


def test_compile_for_px4_on_the_command_line(tmp_path, demo_fences, capsys):
    out = tmp_path / "px4.plan"
    argv = ["compile", str(demo_fences), "--bbox", "-0.58,51.42,-0.52,51.44", "-o", str(out)]
    assert main([*argv, "--autopilot", "px4"]) == 0
    doc = json.loads(out.read_text())
    assert doc["mission"]["firmwareType"] == 12  # QGroundControl opens it as a PX4 plan
    fence = doc["geoFence"]
    assert "breachReturn" not in fence
    n = sum(len(p["polygon"]) for p in fence["polygons"]) + len(fence["circles"])
    assert 0 < n <= 64
    capsys.readouterr()
    # an ArduPilot storage for a PX4 fence is refused, in one line, naming what fits
    assert main([*argv, "--autopilot", "px4", "--profile", "copter"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "copter is ArduPilot's fence storage" in err[0]
    assert "px4, px4-constrained" in err[0]
    assert main([*argv, "--profile", "px4-constrained"]) == 0  # the profile says PX4
    assert json.loads(out.read_text())["mission"]["firmwareType"] == 12


def test_a_preset_for_the_other_autopilot_is_refused_without_a_vehicle(demo_fences, capsys):
    argv = ["upload", str(demo_fences), "--bbox", "-0.58,51.42,-0.52,51.44", "--dry-run",
            "--allow-unsigned"]  # fmt: skip
    assert main([*argv, "--params", "px4-hold"]) == 2
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert err == ["alphafence upload: error: --params: px4-hold is for PX4; the fence is "
                   "compiled for ArduPilot (--autopilot, --profile)"]  # fmt: skip
    assert main([*argv, "--params", "copter-brake", "--autopilot", "px4"]) == 2
    assert "copter-brake is for ArduPilot; the fence is compiled for PX4" in capsys.readouterr().err
    assert main([*argv, "--params", "px4-hold", "--autopilot", "px4"]) == 0
    assert "fence items ready; nothing sent" in capsys.readouterr().out
