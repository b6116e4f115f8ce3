"""alphafence route and check-mission, end to end on a small synthetic fence file."""

import json

import numpy as np
import pytest
import shapely

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.flights.mission import read_mission
from alphafence.geo.frame import LocalFrame

LON0, LAT0 = 14.45, 35.88
FRAME = LocalFrame(LON0, LAT0)
PNG = b"\x89PNG\r\n\x1a\n"


def ll(x, y):
    """metres east/north of the scene origin -> 'LAT,LON' (command-line order)."""
    lon, lat = FRAME.to_wgs84(x, y)
    return f"{float(lat):.8f},{float(lon):.8f}"


def feature(site_id, kind, geom_local):
    g = FRAME.geom_to_wgs84(geom_local)
    return {
        "type": "Feature",
        "properties": {"site_id": site_id, "kind": kind, "name": site_id.split("/")[0]},
        "geometry": shapely.geometry.mapping(g),
    }


@pytest.fixture
def fences(tmp_path):
    wall = shapely.box(-20, -300, 20, 300)
    ring = shapely.box(400, -100, 600, 100).difference(shapely.box(420, -80, 580, 80))
    feats = [
        feature("prison/1", "keep_out", wall),
        feature("prison/1", "warning", wall.buffer(30)),
        feature("airfield/2", "keep_out", ring),
    ]
    path = tmp_path / "fences.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def test_route_writes_plan_waypoints_and_figure(fences, tmp_path, capsys):
    plan, wpl, png = tmp_path / "m.plan", tmp_path / "m.waypoints", tmp_path / "m.png"
    code = main(
        ["route", str(fences), "--from", ll(-200, 0), "--to", ll(200, 0), "--alt", "40"]
        + ["--clearance", "25", "-o", str(plan), "--waypoints", str(wpl), "--figure", str(png)]
    )
    assert code == 0, capsys.readouterr()
    doc = json.loads(plan.read_text())
    items = doc["mission"]["items"]
    cmds = [it["command"] for it in items]
    assert cmds[0] == 22 and cmds[-1] == 20 and set(cmds[1:-1]) == {16}
    assert all(it["frame"] == 3 for it in items[:-1])
    assert all(it["params"][6] == 40 for it in items[:-1])
    lat, lon = items[0]["params"][4:6]  # plan order is lat, lon
    x, y = FRAME.to_local(lon, lat)
    assert abs(x + 200) < 0.05 and abs(y) < 0.05
    # the route: every leg at least the clearance from the wall, checked independently
    pts = np.array([FRAME.to_local(it["params"][5], it["params"][4]) for it in items[:-1]])
    legs = shapely.linestrings(np.stack([pts[:-1], pts[1:]], axis=1))
    assert shapely.distance(legs, shapely.box(-20, -300, 20, 300)).min() >= 25.0
    text = wpl.read_text().splitlines()
    assert text[0] == "QGC WPL 110" and len(text) == len(items) + 2
    assert png.read_bytes().startswith(PNG)
    # the written mission passes check-mission (plan and waypoint file)
    for mission in (plan, wpl):
        assert (
            main(["check-mission", str(mission), "--fences", str(fences), "--clearance", "25"]) == 0
        )
    out = capsys.readouterr().out
    assert "0 cross a keep-out fence, 0 graze one" in out


def test_route_start_inside_fence_is_one_line_and_writes_nothing(fences, tmp_path, capsys):
    plan = tmp_path / "m.plan"
    code = main(["route", str(fences), "--from", ll(0, 0), "--to", ll(200, 0), "-o", str(plan)])
    err = capsys.readouterr().err.strip()
    assert code == 1 and not plan.exists()
    assert len(err.splitlines()) == 1
    assert "no route: the start is inside keep-out fence prison/1 (prison)" in err


def test_route_enclosed_goal_is_named(fences, tmp_path, capsys):
    code = main(
        [
            "route",
            str(fences),
            "--from",
            ll(200, 0),
            "--to",
            ll(500, 0),
            "-o",
            str(tmp_path / "m.plan"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 1
    assert "the goal is enclosed by keep-out fence airfield/2" in err


@pytest.mark.parametrize("bad", ["35.9", "x,y", "95,14"])
def test_route_bad_position_is_an_input_error(fences, tmp_path, capsys, bad):
    code = main(
        ["route", str(fences), "--from", bad, "--to", ll(200, 0), "-o", str(tmp_path / "m")]
    )
    assert code == 2
    assert "--from" in capsys.readouterr().err


def _plan(tmp_path, pts, name="bad.plan"):
    items = [
        {
            "type": "SimpleItem",
            "command": 16,
            "frame": 3,
            "doJumpId": i + 1,
            "params": [0, 0, 0, None, *map(float, ll(*p).split(",")), 30],
        }
        for i, p in enumerate(pts)
    ]
    home = [float(v) for v in ll(*pts[0]).split(",")]
    doc = {"fileType": "Plan", "mission": {"items": items, "plannedHomePosition": [*home, 0]}}
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def test_check_mission_lists_crossing_legs_and_fails(fences, tmp_path, capsys):
    mission = _plan(tmp_path, [(-200, 0), (-200, 50), (200, 50)])
    code = main(["check-mission", str(mission), "--fences", str(fences)])
    out = capsys.readouterr().out
    assert code == 1
    assert "CROSSES" in out and "prison/1" in out
    assert "1 cross a keep-out fence" in out


def test_check_mission_grazing_is_listed_but_passes(fences, tmp_path, capsys):
    # a leg passing 10 m north of the wall's end: grazes with the default 20 m clearance
    mission = _plan(tmp_path, [(-200, 310), (200, 310)])
    code = main(["check-mission", str(mission), "--fences", str(fences)])
    out = capsys.readouterr().out
    assert code == 0
    assert "grazes" in out and "0 cross a keep-out fence, 1 graze one" in out


def test_check_mission_reads_waypoint_files(fences, tmp_path, capsys):
    a = [float(v) for v in ll(-200, 0).split(",")]
    b = [float(v) for v in ll(200, 0).split(",")]
    rows = ["QGC WPL 110"]
    for seq, (lat, lon) in enumerate([a, a, b]):
        rows.append(f"{seq}\t0\t3\t16\t0\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t30\t1")
    path = tmp_path / "m.waypoints"
    path.write_text("\n".join(rows) + "\n")
    assert [w.label for w in read_mission(path)][0] == "home"
    assert main(["check-mission", str(path), "--fences", str(fences)]) == 1


def test_check_mission_bad_input(fences, tmp_path, capsys):
    assert main(["check-mission", str(tmp_path / "none.plan"), "--fences", str(fences)]) == 2
    assert "no such file" in capsys.readouterr().err
    p = tmp_path / "x.plan"
    p.write_text('{"mission": {"items": [{"type": "SimpleItem", "command": 16, "params": [0]}]}}')
    assert main(["check-mission", str(p), "--fences", str(fences)]) == 2
    err = capsys.readouterr().err
    assert "x.plan: item 1: params must be a list of 7 values" in err


def test_fence_records_round_trip(fences):
    assert {r.kind for r in read_fences(fences)} == {"keep_out", "warning"}


def test_route_takes_negative_coordinates_after_a_space(tmp_path, capsys):
    # south and west of Greenwich: "--from -35.36,149.16" is a value, not an unknown option
    frame = LocalFrame(-58.4, -34.6)  # Buenos Aires: both coordinates negative
    wall = frame.geom_to_wgs84(shapely.box(-20, -300, 20, 300))
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"site_id": "prison/1", "kind": "keep_out", "name": "prison"},
                "geometry": shapely.geometry.mapping(wall),
            }
        ],
    }
    fences = tmp_path / "south.geojson"
    fences.write_text(json.dumps(doc))

    def at(x, y):
        lon, lat = frame.to_wgs84(x, y)
        return f"{float(lat):.8f},{float(lon):.8f}"

    plan = tmp_path / "m.plan"
    start, goal = at(-200, 0), at(200, 0)
    assert start.startswith("-") and goal.startswith("-")
    code = main(["route", str(fences), "--from", start, "--to", goal, "-o", str(plan)])
    assert code == 0, capsys.readouterr()
    lat, lon = json.loads(plan.read_text())["mission"]["items"][0]["params"][4:6]
    x, y = frame.to_local(lon, lat)
    assert abs(x + 200) < 0.05 and abs(y) < 0.05
