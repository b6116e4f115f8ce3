"""Home (and the vehicle's position) as inputs of the compile: no item the compiler chooses (a
simplification, a circle, a merge) covers them or comes within the clearance, as ArduPilot
and PX4 read the items (the tests' models, written from their source); only a fence that
itself holds home is refused, by its name."""

import json
import math

import numpy as np
import pytest
import shapely
import shapely.geometry
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard import clear as clear_module
from alphafence.onboard.clear import KeepClear
from alphafence.onboard.compile import compile_fences

from . import ardupilot_model, px4_model
from .helpers import VerifyFrame
from .test_compile import contained, onboard_geometry
from .zone_samples import star_polygon

HOME = (14.4775, 35.866)  # Luqa: the SITL fixtures' malta_airport home (lon, lat)
BOX = (14.46, 35.855, 14.50, 35.88)  # the operating box of the first report


def holds_home(items, home, autopilot):
    """Whether the vehicle holding ``items`` is in breach at ``home`` (ArduPilot), or drops
    an area as the fence loads (PX4), by the tests' models."""
    if autopilot == "px4":
        return px4_model.kept(items, home, (home[1], home[0])) < len(
            ardupilot_model.fence_shapes(items)
        )
    return bool(ardupilot_model.breached(items, home[0], home[1])[0])


def inradius(autopilot):
    """The radius each autopilot surely holds of a circle item (its own distance)."""
    return px4_model.circle_inradius_m if autopilot == "px4" else ardupilot_model.circle_inradius_m


def exclusion_distance_m(items, home):
    """Metres from ``home`` to the nearest exclusion item, read as ArduPilot reads it."""
    verify = VerifyFrame(*home)
    polys, discs = onboard_geometry(items, verify, inradius=ardupilot_model.circle_outradius_m)
    d = [p.distance(shapely.Point(0, 0)) for p in polys]
    d += [max(math.hypot(x, y) - r, 0.0) for x, y, r in discs]
    return min(d, default=math.inf)


def far_from(records, box, distance_m=2000.0, slack_m=10.0):
    """The site ids of ``records`` farther than about ``distance_m`` from ``box`` (a compile
    for the box leaves them out)."""
    frame = LocalFrame.around(box)
    near = frame.read_geom(box)
    return [r.site_id for r in records
            if shapely.distance(frame.read_geom(r.geometry), near) > distance_m - slack_m]  # fmt: skip


def assert_clear_and_holding(records, items, dropped, autopilot, home, clearance=25.0):
    """``items`` leave ``home`` clear as the autopilot reads them, and hold every keep-out
    fence of ``records`` but those ``dropped`` (too far to compile)."""
    assert not holds_home(items, home, autopilot)
    assert exclusion_distance_m(items, home) >= clearance - 0.5
    verify = VerifyFrame(*home)
    polys, discs = onboard_geometry(items, verify, inradius(autopilot))
    for rec in records:
        if rec.kind == "keep_out" and rec.site_id not in set(dropped):
            for part in shapely.get_parts(shapely.make_valid(verify.local(rec.geometry))):
                assert contained(part, polys, discs), rec.site_id


@pytest.fixture(scope="module")
def malta_fences(malta, tmp_path_factory):
    out = tmp_path_factory.mktemp("malta-home") / "fences.geojson"
    assert main(["build", str(malta), "-o", str(out), "-q"]) == 0
    return read_fence_file(out)


@pytest.mark.parametrize("profile", ["px4", "copter"])
def test_the_malta_box_compiles_clear_of_home_and_still_holds_every_fence(malta_fences, profile):
    area = shapely.box(*BOX)
    autopilot = PROFILES[profile].autopilot
    result = compile_fences(malta_fences, area, PROFILES[profile], 2000.0,
                            keep_clear=KeepClear.of(HOME))  # fmt: skip
    assert_clear_and_holding(malta_fences, result.items, result.dropped, autopilot, HOME)


def test_broken_without_home_the_px4_compile_covers_it(malta_fences):
    """The first report, kept as the check's broken case: compiled blind to home, PX4's
    budget merges a 7.9 km² exclusion over it."""
    result = compile_fences(malta_fences, shapely.box(*BOX), PROFILES["px4"], 2000.0)
    assert holds_home(result.items, HOME, "px4")


def test_broken_a_clearance_that_allows_anything_is_caught(malta_fences, monkeypatch):
    monkeypatch.setattr(clear_module.LocalClear, "allows", lambda *a: True)
    monkeypatch.setattr(clear_module.LocalClear, "spans", lambda self, h, n: np.zeros(len(h), bool))
    monkeypatch.setattr(clear_module, "check_held", lambda *a, **k: None)
    monkeypatch.setattr("alphafence.onboard.compile.check_held", lambda *a, **k: None)
    result = compile_fences(malta_fences, shapely.box(*BOX), PROFILES["px4"], 2000.0,
                            keep_clear=KeepClear.of(HOME))  # fmt: skip
    assert holds_home(result.items, HOME, "px4")


@st.composite
def scenes(draw):
    """Keep-out polygons round a point, a home somewhere in the box, and a budget."""
    lon0 = draw(st.floats(-170, 170))
    lat0 = draw(st.floats(-70, 70))
    frame = LocalFrame(lon0, lat0)
    records = []
    for k in range(draw(st.integers(2, 16))):
        poly = star_polygon(draw, st, 1500, (3, 24), (10, 300))
        if poly.is_valid and poly.area > 10:
            records.append(FenceRecord(f"test/{k}", "keep_out", frame.geom_to_wgs84(poly)))
    hx, hy = draw(st.floats(-800, 800)), draw(st.floats(-800, 800))
    home = tuple(float(v) for v in frame.to_wgs84(hx, hy))
    box = frame.geom_to_wgs84(shapely.box(-1000, -1000, 1000, 1000))
    return (
        records,
        home,
        box,
        draw(st.sampled_from(["copter", "px4"])),
        draw(st.sampled_from([8, 16, 70])),
    )


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
@example(([FenceRecord("test/0", "keep_out", shapely.box(14.476, 35.865, 14.479, 35.867))],
          HOME, shapely.box(*BOX), "px4", 70))  # fmt: skip
def test_no_compiled_item_covers_home_unless_a_fence_does(scene):
    records, home, box, profile, max_items = scene
    if not records:
        return
    autopilot = PROFILES[profile].autopilot
    verify = VerifyFrame(*home)
    own = [shapely.make_valid(verify.local(r.geometry)) for r in records]
    d_real = min(g.distance(shapely.Point(0, 0)) for g in own)
    try:
        result = compile_fences(records, box, PROFILES[profile], 5000.0, max_items=max_items,
                                keep_clear=KeepClear.of(home))  # fmt: skip
    except InputError as err:
        if "keep-out fence" in str(err):  # a fence itself holds home: it is named
            assert d_real < 0.5, (str(err), d_real)  # as read, a spike may reach it
            named = str(err).split(": ")[1]
            assert any(named == r.site_id for r in records)
            return
        assert "do not fit" in str(err) or "leaves home" in str(err), str(err)
        return
    assert d_real >= 0.1  # else it is refused
    assert not holds_home(result.items, home, autopilot)
    # the clearance, or what the fences themselves leave less their pads
    assert exclusion_distance_m(result.items, home) >= min(25.0, d_real - 0.1) - 0.5
    polys, discs = onboard_geometry(result.items, verify, inradius(autopilot))
    for g in own:
        for part in shapely.get_parts(g):
            assert contained(part, polys, discs)


def test_a_fence_over_home_is_refused_by_name(tmp_path, capsys):
    frame = LocalFrame(*HOME)
    square = frame.geom_to_wgs84(shapely.box(-50, -50, 50, 50))
    fences = tmp_path / "f.geojson"
    props = {"site_id": "prison/way/7", "kind": "keep_out", "name": "Kordin"}
    feature = {"type": "Feature", "properties": props, "geometry": shapely.geometry.mapping(square)}
    fences.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    argv = ["compile", str(fences), "--bbox", ",".join(map(str, BOX)), "-o",
            str(tmp_path / "o.plan"), "--home", f"{HOME[1]},{HOME[0]}"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "prison/way/7 (Kordin): home (35.8660000,14.4775000) is inside this keep-out" in err[0]
    assert not (tmp_path / "o.plan").exists()
    # 100 m east, it is left clear (a 25 m clearance, and the fence's own 50 m)
    assert main([*argv[:-1], f"{HOME[1]},{HOME[0] + 0.0011}"]) == 0


def test_home_outside_every_keep_in_fence_is_refused(tmp_path, capsys):
    frame = LocalFrame(*HOME)
    keep_in = frame.geom_to_wgs84(shapely.box(500, 500, 900, 900))
    with pytest.raises(InputError, match="outside every keep-in fence \\(park/1\\)"):
        compile_fences([FenceRecord("park/1", "keep_in", keep_in)], shapely.box(*BOX),
                       PROFILES["copter"], keep_clear=KeepClear.of(HOME))  # fmt: skip
    # the vehicle's position in flight is no refusal: it constrains what it can
    result = compile_fences([FenceRecord("park/1", "keep_in", keep_in)], shapely.box(*BOX),
                            PROFILES["copter"], keep_clear=KeepClear.of(
                                None, HOME))  # fmt: skip
    assert len(result.items) >= 4


def test_a_keep_in_fence_is_stored_holding_home_the_clearance_inside():
    frame = LocalFrame(*HOME)
    # a keep-in area with home 40 m inside a finger (80 m wide) off a large square: simplified
    # inward to four vertices, the square alone is what is stored, and home is left out
    shape = shapely.union(shapely.box(-500, -1200, 500, -200), shapely.box(-40, -200, 40, 100))
    fence = [FenceRecord("park/1", "keep_in", frame.geom_to_wgs84(shape))]
    home_xy = shapely.Point(0, 0)
    # blind to home (the broken case), four items store the square: the vehicle could not arm
    blind = compile_fences(fence, shapely.box(*BOX), PROFILES["copter"], max_items=4)
    assert holds_home(blind.items, HOME, "ardupilot")
    try:  # round home, four items either leave it inside or do not fit
        four = compile_fences(fence, shapely.box(*BOX), PROFILES["copter"], max_items=4,
                              keep_clear=KeepClear.of(HOME))  # fmt: skip
        assert not holds_home(four.items, HOME, "ardupilot")
    except InputError as err:
        assert "do not fit" in str(err)
    result = compile_fences(fence, shapely.box(*BOX), PROFILES["copter"],
                            keep_clear=KeepClear.of(HOME))  # fmt: skip
    assert not holds_home(result.items, HOME, "ardupilot")
    ring_items = [(i.lon, i.lat) for i in result.items]
    stored = VerifyFrame(*HOME).local(shapely.Polygon(ring_items))
    assert stored.covers(home_xy) and stored.boundary.distance(home_xy) >= 25.0 - 0.5


def _fences_file(tmp_path, boxes):
    """A fence GeoJSON of keep-out squares (metric boxes round HOME)."""
    frame = LocalFrame(*HOME)
    features = [
        {"type": "Feature",
         "properties": {"site_id": f"site/{k}", "kind": "keep_out"},
         "geometry": shapely.geometry.mapping(frame.geom_to_wgs84(shapely.box(*b)))}
        for k, b in enumerate(boxes)
    ]  # fmt: skip
    path = tmp_path / "f.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


def _upload_to_fake(argv, home):
    import asyncio

    from tests.fake_vehicle import FakeVehicle

    async def run():
        async with FakeVehicle(home=home) as fake:
            full = [*argv, "--connect", fake.url, "--allow-unsigned", "--link", "pymavlink"]
            return await asyncio.to_thread(main, full), fake

    return asyncio.run(run())


# sixteen squares in a ring 60-90 m round home: four items budget them into merges over it
RING = [(60 * math.cos(a) - 15, 60 * math.sin(a) - 15, 60 * math.cos(a) + 15, 60 * math.sin(a) + 15)
        for a in np.linspace(0, 2 * math.pi, 16, endpoint=False)]  # fmt: skip


def test_upload_reads_the_vehicles_home_and_compiles_round_it(tmp_path, capsys):
    path = _fences_file(tmp_path, RING)
    argv = ["upload", str(path), "--bbox", ",".join(map(str, BOX)), "--autopilot", "ardupilot",
            "--home-clearance", "10", "--items"]  # fmt: skip
    code, fake = _upload_to_fake([*argv, "12"], HOME)
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "home 35.8660000,14.4775000: the fence leaves them 10 m clear" in out.out
    assert len(fake.fence) == 12 and not ardupilot_model.breached(fake.fence, *HOME).any()
    # six items cannot hold the ring without a merge over home: refused, nothing sent
    code, fake = _upload_to_fake([*argv, "6"], HOME)
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert code == 2 and len(err) == 1, err
    assert "no merge may come within 10 m of home" in err[0]
    assert not fake.received("MISSION_COUNT") and not fake.fence
    # broken case: a vehicle without a home gets a fence blind to it (and is told so): one
    # circle over the whole ring, home in it
    code, fake = _upload_to_fake([*argv, "6"], None)
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "the vehicle has no home yet" in out.err and "give --home" in out.err
    assert ardupilot_model.breached(fake.fence, *HOME).any()
