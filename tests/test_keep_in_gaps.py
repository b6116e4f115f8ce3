"""Several keep-in areas under an autopilot that reads inclusions as their intersection (PX4;
ArduPilot without FENCE_OPTIONS' union bit): one inclusion round them and an exclusion per gap.
Read by the tests' models of PX4 and ArduPilot (written from their source), no point outside
every area is allowed, and home, inside one, is."""

import math

import numpy as np
import pytest
import shapely
import shapely.geometry
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_EXCLUSION
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.clear import KeepClear
from alphafence.onboard.compile import compile_fences

from . import ardupilot_model, px4_model
from .zone_samples import star_polygon

ORIGIN = (-0.55, 51.43)


def allowed(items, lon, lat, autopilot, home):
    """Where the vehicle holding ``items`` may fly, by the model of its autopilot (PX4: the
    areas home breaches dropped first, as it loads the fence)."""
    if autopilot == "px4":
        return ~px4_model.breached(items, lon, lat, (home[1], home[0]), home=home)
    return ~ardupilot_model.breached(items, lon, lat, union=False)


def in_some_area(records, lon, lat):
    """Inside at least one keep-in area, as read (straight lon/lat edges)."""
    inside = np.zeros(np.shape(lon), bool)
    for r in records:
        for part in shapely.get_parts(r.geometry):
            ring = np.asarray(part.exterior.coords)
            inside |= ~ardupilot_model.polygon_outside(lat, lon, ring[:, 1], ring[:, 0])
    return inside


def samples(records, n=6000, seed=0):
    """Points over the areas' hull and on a fine lattice along every area's rim."""
    lon0, lat0, lon1, lat1 = shapely.total_bounds([r.geometry for r in records])
    rng = np.random.default_rng(seed)
    lon = rng.uniform(lon0 - 1e-3, lon1 + 1e-3, n)
    lat = rng.uniform(lat0 - 1e-3, lat1 + 1e-3, n)
    rims = []
    for r in records:
        ring = shapely.LineString(r.geometry.exterior.coords)
        pts = shapely.get_coordinates(
            shapely.line_interpolate_point(ring, np.linspace(0, 1, 400), normalized=True)
        )
        for d in (-2e-6, 0.0, 2e-6):  # just outside, on and just inside, east and north
            rims.append(pts + [d, 0.0])
            rims.append(pts + [0.0, d])
    rim = np.vstack(rims)
    return np.concatenate([lon, rim[:, 0]]), np.concatenate([lat, rim[:, 1]])


def violations(records, items, autopilot, home):
    lon, lat = samples(records)
    bad = allowed(items, lon, lat, autopilot, home) & ~in_some_area(records, lon, lat)
    return int(bad.sum())


def areas(boxes):
    frame = LocalFrame(*ORIGIN)
    return [FenceRecord(f"area/{k}", "keep_in", frame.geom_to_wgs84(shapely.box(*b)))
            for k, b in enumerate(boxes)]  # fmt: skip


THREE = [(-300, -300, 300, 300), (4700, -300, 5300, 300), (2000, 1500, 2600, 2100)]
HOME = tuple(float(v) for v in LocalFrame(*ORIGIN).to_wgs84(0.0, 0.0))


def compiled(records, profile, home=HOME, **kw):
    frame = LocalFrame(*ORIGIN)
    area = frame.geom_to_wgs84(shapely.box(-500, -500, 5500, 2500))
    return compile_fences(records, area, PROFILES[profile], 3000.0,
                          keep_clear=KeepClear.of(home), **kw)  # fmt: skip


@pytest.mark.parametrize("profile, rule", [("px4", None), ("copter", "intersection")])
def test_three_areas_are_one_inclusion_and_their_gaps(profile, rule):
    records = areas(THREE)
    result = compiled(records, profile, inclusions=rule)
    autopilot = PROFILES[profile].autopilot
    assert sum(p.inclusion for p in result.pieces) == 1
    assert violations(records, result.items, autopilot, HOME) == 0
    # home, in the west area, is allowed; so is the middle of every area
    frame = LocalFrame(*ORIGIN)
    lon, lat = frame.to_wgs84(np.array([0.0, 5000.0, 2300.0]), np.array([0.0, 0.0, 1800.0]))
    assert allowed(result.items, lon, lat, autopilot, HOME).all()
    # and between them is not
    lon, lat = frame.to_wgs84(np.array([2500.0, 1000.0]), np.array([0.0, 900.0]))
    assert not allowed(result.items, lon, lat, autopilot, HOME).any()


@pytest.mark.parametrize("profile", ["px4", "copter"])
def test_broken_a_gap_left_out_is_caught(profile):
    records = areas(THREE)
    result = compiled(records, profile, inclusions="intersection")
    autopilot = PROFILES[profile].autopilot
    gap = next(k for k, it in enumerate(result.items) if it.command == POLYGON_EXCLUSION)
    n = int(result.items[gap].param1)
    broken = result.items[:gap] + result.items[gap + n :]
    assert violations(records, broken, autopilot, HOME) > 0


def test_the_union_rule_keeps_the_areas_as_they_are():
    records = areas(THREE)
    result = compiled(records, "copter")  # ArduPilot with the union bit: three inclusions
    assert sum(p.inclusion for p in result.pieces) == 3
    assert not any(s.startswith("keep-in-gap") for p in result.pieces for s in p.sources)


def test_areas_that_cannot_fit_are_refused_in_one_line():
    many = [(x, y, x + 200, y + 200) for x in range(0, 5000, 700) for y in (0, 1400)]
    with pytest.raises(InputError, match="do not fit a px4") as err:
        compiled(areas(many), "px4", home=tuple(LocalFrame(*ORIGIN).to_wgs84(100.0, 100.0)),
                 max_items=12)  # fmt: skip
    assert "\n" not in str(err.value)


@st.composite
def area_sets(draw):
    lon0, lat0 = draw(st.floats(-170, 170)), draw(st.floats(-65, 65))
    frame = LocalFrame(lon0, lat0)
    polys = []
    for _ in range(draw(st.integers(2, 4))):
        poly = star_polygon(draw, st, 3000, (3, 10), (150, 700))
        # valid in lon/lat too, as a build writes its fences (a ring that doubles back on
        # itself is read one way by GEOS and another by an autopilot's crossing test)
        if poly.is_valid and poly.area > 1e4 and frame.geom_to_wgs84(poly).is_valid:
            polys.append(poly)
    records = [FenceRecord(f"area/{k}", "keep_in", frame.geom_to_wgs84(p))
               for k, p in enumerate(polys)]  # fmt: skip
    home = None
    if polys:
        inner = shapely.buffer(polys[0], -40.0)
        if not inner.is_empty:
            home = tuple(float(v) for v in frame.to_wgs84(*shapely.get_coordinates(
                shapely.point_on_surface(inner))[0]))  # fmt: skip
    box = frame.geom_to_wgs84(shapely.box(-4000, -4000, 4000, 4000))
    return records, home, box, draw(st.sampled_from(["px4", "copter"]))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(area_sets())
def test_no_point_outside_every_area_is_allowed(scene):
    records, home, box, profile = scene
    if len(records) < 2 or home is None:
        return
    autopilot = PROFILES[profile].autopilot
    try:
        result = compile_fences(records, box, PROFILES[profile], 6000.0,
                                keep_clear=KeepClear.of(home), inclusions="intersection")  # fmt: skip
    except InputError as err:
        assert "do not fit" in str(err) or "keep-in" in str(err), str(err)
        return
    assert violations(records, result.items, autopilot, home) == 0
    assert allowed(result.items, *home, autopilot, home).all()
    assert math.isfinite(result.loss_m2)


def _upload_to_fake(tmp_path, path, firmware, extra=()):
    import asyncio

    from alphafence.cli import main
    from tests.fake_vehicle import FakeVehicle

    params = {"FENCE_ENABLE": 0, "FENCE_TYPE": 7, "FENCE_ACTION": 1, "FENCE_OPTIONS": 1}

    async def run():
        async with FakeVehicle(params=params, firmware=firmware, home=HOME) as fake:
            argv = ["upload", str(path), "--connect", fake.url, "--allow-unsigned",
                    "--link", "pymavlink", *extra]  # fmt: skip
            return await asyncio.to_thread(main, argv), fake

    return asyncio.run(run())


def _fences_file(tmp_path, records):
    import json

    features = [{"type": "Feature", "properties": {"site_id": r.site_id, "kind": r.kind},
                 "geometry": shapely.geometry.mapping(r.geometry)} for r in records]  # fmt: skip
    path = tmp_path / "areas.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


BOX_ARGS = ("--bbox", "-0.56,51.42,-0.47,51.45")


def test_firmware_older_than_the_union_bit_gets_the_gaps_never_a_silent_intersection(
    tmp_path, capsys
):
    import shapely.geometry  # noqa: F401 - mapping

    records = areas(THREE)
    code, fake = _upload_to_fake(tmp_path, _fences_file(tmp_path, records), (4, 4, 0), BOX_ARGS)
    out = capsys.readouterr()
    assert code == 0, out.err
    commands = [i.command for i in fake.fence]
    inclusions = sum(
        1 for k, c in enumerate(commands) if c == 5001 and (k == 0 or commands[k - 1] != 5001)
    )
    assert inclusions == 1 and POLYGON_EXCLUSION in commands
    assert not fake.received("PARAM_SET")  # no union bit: this firmware does not read it
    said = out.out.replace("\n", " ")
    assert "keep-in areas compiled as one inclusion round them and" in said
    assert "ArduPilot 4.4.0 has FENCE_OPTIONS but does not read its union bit" in said
    assert violations(records, fake.fence, "ardupilot", HOME) == 0
    # the same fence on 4.5: the areas as they are, and the union bit set
    code, fake = _upload_to_fake(tmp_path, _fences_file(tmp_path, records), (4, 5, 0), BOX_ARGS)
    out = capsys.readouterr()
    assert code == 0, out.err
    assert fake.params["FENCE_OPTIONS"] == 3 and "as their union" in out.out


def test_an_onboard_file_of_two_inclusions_is_refused_on_firmware_that_intersects(tmp_path, capsys):
    from alphafence.fencefiles.qgc_plan import dumps, plan_document
    from alphafence.mavlink.items import POLYGON_INCLUSION, FenceItem

    frame = LocalFrame(*ORIGIN)
    items = []
    for b in THREE[:2]:
        xs, ys = shapely.get_coordinates(shapely.box(*b).exterior)[:-1].T
        lon, lat = frame.to_wgs84(xs, ys)
        items += [FenceItem(POLYGON_INCLUSION, 4.0, round(float(a), 7), round(float(c), 7))
                  for a, c in zip(lon, lat)]  # fmt: skip
    path = tmp_path / "two.plan"
    path.write_text(dumps(plan_document(items)))
    code, fake = _upload_to_fake(tmp_path, path, (4, 4, 0))
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert code == 3 and len(err) == 1, err
    assert "ArduPilot 4.4.0 has FENCE_OPTIONS but does not read its union bit" in err[0]
    assert "nothing was sent" in err[0]
    assert not fake.received("MISSION_COUNT") and not fake.received("PARAM_SET")
