"""Two keep-in areas as the operator means them (fly in either) and as ArduPilot reads them:
the monitor's own fences are their union, a vehicle's inclusions follow its FENCE_OPTIONS, and
``upload`` sets FENCE_OPTIONS bit 1 for more than one inclusion (refusing, with nothing sent,
on firmware without the parameter). ArduPilot's own verdicts: tests/test_inclusions_sitl.py."""

from __future__ import annotations

import asyncio
import json

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.sample import Sample
from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import dumps, plan_document
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.inclusions import inclusion_count
from alphafence.mavlink.items import POLYGON_EXCLUSION, POLYGON_INCLUSION, FenceItem
from alphafence.monitor.onboard import OnboardLayer, load_layer
from tests.fake_vehicle import FakeVehicle

FRAME = LocalFrame(-0.55, 51.43)
WEST, EAST = shapely.box(-300, -300, 300, 300), shapely.box(4700, -300, 5300, 300)


def square_items(box, command=POLYGON_INCLUSION):
    xs, ys = shapely.get_coordinates(box.exterior)[:-1].T
    lon, lat = FRAME.to_wgs84(xs, ys)
    return [FenceItem(command, float(len(xs)), round(float(a), 7), round(float(b), 7))
            for a, b in zip(lon, lat)]  # fmt: skip


TWO_AREAS = square_items(WEST) + square_items(EAST)


def areas(union=True):
    records = [FenceRecord(f"area/{k}", "keep_in", FRAME.geom_to_wgs84(b))
               for k, b in enumerate((WEST, EAST))]  # fmt: skip
    return FenceSet(records, FRAME, keep_in_union=union)


@pytest.mark.parametrize("union, at_home, between", [(True, [], [0, 1]), (False, [1], [0, 1])])
def test_keep_in_fences_combine_by_the_rule(union, at_home, between):
    fs = areas(union)
    assert fs.check(0.0, 0.0, 10.0).outside_keep_in == at_home
    assert fs.check(2500.0, 0.0, 10.0).outside_keep_in == between
    assert fs.check(5000.0, 0.0, 10.0).outside_keep_in == ([] if union else [0])
    assert (fs.near(0.0, 0.0, 10.0, 1.0) is None) is union


@pytest.mark.parametrize("union", [False, True])
def test_the_onboard_layer_reads_inclusions_by_the_vehicles_rule(union):
    full = areas()
    layer = OnboardLayer.from_items(TWO_AREAS, FRAME, union=union)
    check = layer.index.check(0.0, 0.0, 10.0, 0.0, 0.0, 1.0)
    breach = bool(check.outside_keep_in) or bool(check.inside_keep_out)
    assert breach is (not union)  # at home, in the west area only
    # leaving one area for the other is predicted as a breach only where the vehicle says so
    lon, lat = FRAME.to_wgs84(0.0, 0.0)
    layer2, events = load_layer(None, TWO_AREAS, full, at=Sample(0.0, lat, lon, 10.0), union=union)
    assert events[0]["inclusions"] == ("union" if union else "intersection")
    assert ("warning" in events[0]) is (not union)
    assert layer2.breached(lon, lat) is (not union)


def test_plan_says_it_needs_the_union_and_upload_dry_run_says_it_sets_it(tmp_path, capsys):
    doc = plan_document(TWO_AREAS)
    assert doc["geoFence"]["alphafence"]["inclusion_areas"] == 2
    assert "FENCE_OPTIONS" in doc["geoFence"]["alphafence"]["requires"]
    one = plan_document(square_items(WEST) + square_items(shapely.box(0, 0, 50, 50), 5002))
    assert "alphafence" not in one["geoFence"]
    path = tmp_path / "areas.plan"
    path.write_text(dumps(doc))
    assert main(["upload", str(path), "--dry-run", "--allow-unsigned"]) == 0
    assert "also sets FENCE_OPTIONS bit 1" in capsys.readouterr().out.replace("\n", "")


def test_inclusions_are_counted_as_the_loader_groups_them():
    assert inclusion_count(TWO_AREAS) == 2
    assert inclusion_count(square_items(WEST) + square_items(EAST, POLYGON_EXCLUSION)) == 1


PARAMS = {"FENCE_ENABLE": 0, "FENCE_TYPE": 7, "FENCE_ACTION": 1, "FENCE_MARGIN": 3.0}


def upload(tmp_path, params, items=TWO_AREAS):
    path = tmp_path / "areas.plan"
    path.write_text(dumps(plan_document(items)))

    async def run():
        async with FakeVehicle(params=params) as fake:
            argv = ["upload", str(path), "--connect", fake.url, "--allow-unsigned"]
            code = await asyncio.to_thread(main, [*argv, "--link", "pymavlink"])
            return code, fake

    return asyncio.run(run())


def test_upload_sets_the_union_bit_keeping_the_others(tmp_path, capsys):
    code, fake = upload(tmp_path, {**PARAMS, "FENCE_OPTIONS": 1})
    assert code == 0, capsys.readouterr()
    assert fake.params["FENCE_OPTIONS"] == 3  # bit 0 kept, bit 1 set
    assert len(fake.fence) == len(TWO_AREAS)
    assert "reads its 2 inclusion areas as their union" in capsys.readouterr().out


def test_upload_refuses_firmware_without_fence_options_and_sends_nothing(tmp_path, capsys):
    code, fake = upload(tmp_path, PARAMS)  # no FENCE_OPTIONS: the fake does not answer it
    assert code == 3
    assert not fake.received("MISSION_COUNT") and not fake.received("PARAM_SET")
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(err) == 1 and "has no FENCE_OPTIONS" in err[0] and "nothing was sent" in err[0]


def test_one_inclusion_needs_no_option(tmp_path, capsys):
    code, fake = upload(tmp_path, PARAMS, square_items(WEST))
    assert code == 0, capsys.readouterr()
    assert "FENCE_OPTIONS" not in fake.params and not fake.received("PARAM_SET")


def test_build_note_for_two_keep_in_areas(tmp_path, capsys):
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"alphafence:kind": "keep_in", "osm_id": str(k)},
         "geometry": shapely.geometry.mapping(FRAME.geom_to_wgs84(b))}
        for k, b in enumerate((WEST, EAST))]}  # fmt: skip
    src = tmp_path / "areas.geojson"
    src.write_text(json.dumps(doc))
    out = tmp_path / "f.geojson"
    assert main(["build", str(src), "-o", str(out), "--plan", str(tmp_path / "f.plan"), "-q"]) == 0
    assert "2 inclusion areas: ArduPilot needs FENCE_OPTIONS" in capsys.readouterr().err.replace(
        "\n", " "
    )


def test_upload_warns_of_mission_positions_outside_the_fence(tmp_path, capsys):
    """Home in the west area, a waypoint between the areas: the upload says so (by the
    vehicle's reading, the two areas united)."""
    src = tmp_path / "areas.geojson"
    records = [FenceRecord(f"area/{k}", "keep_in", FRAME.geom_to_wgs84(b), 0.0)
               for k, b in enumerate((WEST, EAST))]  # fmt: skip
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": shapely.geometry.mapping(r.geometry),
         "properties": {"site_id": r.site_id, "kind": "keep_in", "margin_m": 0.0}}
        for r in records]}  # fmt: skip
    src.write_text(json.dumps(doc))

    def waypoint(k, x, y):
        lon, lat = FRAME.to_wgs84(x, y)
        return {"type": "SimpleItem", "command": 16, "frame": 3, "doJumpId": k,
                "autoContinue": True, "params": [0, 0, 0, None, float(lat), float(lon), 30]}  # fmt: skip

    home = tuple(float(v) for v in FRAME.to_wgs84(0.0, 0.0))
    mission = plan_document([], home, [waypoint(1, 100.0, 0.0), waypoint(2, 2500.0, 0.0),
                                       waypoint(3, 5000.0, 0.0)])  # fmt: skip
    plan = tmp_path / "mission.plan"
    plan.write_text(dumps(mission))
    argv = ["upload", str(src), "--area", str(plan), "--dry-run", "--allow-unsigned"]
    assert main(argv) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "position 2 breach the fence as the vehicle reads it" in err
    assert "home" not in err.split("position 2")[0].split("warning:")[-1]
