"""``-o`` decides the format by its suffix, for every verb that writes one: ``.plan`` a
QGroundControl plan, ``.waypoints`` a QGC WPL file; any other suffix is refused in one line
naming the suffixes the verb writes, before any work and with nothing written."""

import asyncio
import json

import numpy as np
import pytest

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
from alphafence.flights.mission import read_mission
from alphafence.mavlink.items import POLYGON_EXCLUSION
from tests.fake_vehicle import FakeVehicle

BOX = "-0.58,51.41,-0.52,51.45"  # the demo scene's fences
ENDS = ["--from", "51.4235,-0.575", "--to", "51.438,-0.535"]


@pytest.fixture(scope="module")
def fences(tmp_path_factory):
    out = tmp_path_factory.mktemp("fences") / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(out)]) == 0
    return out


def _argv(verb, fences, out):
    if verb == "compile":
        return ["compile", str(fences), "--bbox", BOX, "-o", str(out)]
    return ["route", str(fences), *ENDS, "-o", str(out)]


@pytest.mark.parametrize("verb", ["compile", "route"])
@pytest.mark.parametrize("suffix", [".geojson", ".txt", ".json", ""])
def test_an_unknown_output_suffix_is_refused_naming_the_known_ones(
    fences, tmp_path, capsys, verb, suffix
):
    out = tmp_path / f"out{suffix}"
    assert main(_argv(verb, fences, out)) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    assert f"{out}: unknown " in err and "(use .plan or .waypoints)" in err
    assert list(tmp_path.iterdir()) == []


def test_compile_writes_a_waypoint_file_for_dot_waypoints(fences, tmp_path):
    assert main(_argv("compile", fences, tmp_path / "o.plan")) == 0
    assert main(_argv("compile", fences, tmp_path / "o.WAYPOINTS")) == 0
    text = (tmp_path / "o.WAYPOINTS").read_text()
    assert text.startswith("QGC WPL 110")
    plan_items = read_plan_fence(tmp_path / "o.plan")
    wpl_items = read_waypoints_fence(tmp_path / "o.WAYPOINTS")
    assert [i.command for i in wpl_items] == [i.command for i in plan_items]
    assert POLYGON_EXCLUSION in {i.command for i in wpl_items}
    assert json.loads((tmp_path / "o.plan").read_text())["fileType"] == "Plan"


def test_route_writes_a_mission_file_for_dot_waypoints(fences, tmp_path):
    assert main(_argv("route", fences, tmp_path / "r.plan")) == 0
    assert main(_argv("route", fences, tmp_path / "r.waypoints")) == 0
    assert (tmp_path / "r.waypoints").read_text().startswith("QGC WPL 110")
    plan = [(w.lat, w.lon) for w in read_mission(tmp_path / "r.plan")]
    wpl = [(w.lat, w.lon) for w in read_mission(tmp_path / "r.waypoints")]
    assert len(wpl) == len(plan) > 2
    assert np.asarray(wpl) == pytest.approx(np.asarray(plan), abs=1e-7)


async def test_download_writes_by_suffix_and_refuses_before_connecting(tmp_path, capsys):
    held = tmp_path / "held.waypoints"
    stored = read_plan_fence("tests/data/ardupilot/fence.plan")
    async with FakeVehicle(fence=stored) as fake:
        argv = ["download", "--connect", fake.url, "--link", "pymavlink", "--timeout", "5"]
        assert await asyncio.to_thread(main, [*argv, "-o", str(tmp_path / "x.geojson")]) == 2
        assert fake.received("MISSION_REQUEST_LIST") == []  # refused before connecting
        assert "(use .plan or .waypoints)" in capsys.readouterr().err
        assert await asyncio.to_thread(main, [*argv, "-o", str(held)]) == 0
    got = read_waypoints_fence(held)
    assert [(i.command, i.lat, i.lon) for i in got] == [
        (i.command, pytest.approx(i.lat, abs=1e-7), pytest.approx(i.lon, abs=1e-7)) for i in stored
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["held.waypoints"]
