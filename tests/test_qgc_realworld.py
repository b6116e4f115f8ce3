"""QGroundControl plans and ArduPilot waypoint files as operators have them (issue 14, items 5-8):
plans in QGC's older item form and version-1 geoFences, the breach return point carried to the
upload, ``upload --dry-run`` checking plan and waypoint fences against the storage profile and
showing what it would send, and ``check-mission`` following every positioned NAV command,
DO_JUMP and keep-in fences.

The samples in ``tests/data/qgc/`` are written the way QGroundControl writes plans
(``QJsonDocument`` indented by 4, keys sorted; ``MissionItem::save``, ``GeoFenceController::save``
of the version each file names) and ArduPilot/MAVProxy write QGC WPL 110 files, in a synthetic
scene (metres east/north of 14.45 E, 35.88 N): a wall ``prison/1`` at x = -20..20 m,
y = -300..300 m, a mast ``mast/4`` of 15 m radius at (-200, 0) and, where a test says so, an
operating area ``area/9`` (-500..500 m square) to stay in.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import pytest
import shapely

from alphafence.cli import main
from alphafence.fencefiles.qgc_plan import read_plan_fence, read_plan_geofence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
from alphafence.flights.mission import read_mission
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)

DATA = Path(__file__).parent / "data" / "qgc"
FRAME = LocalFrame(14.45, 35.88)
PNG = b"\x89PNG\r\n\x1a\n"
OLD_PLAN = DATA / "qgc32-fence-v1-coordinate-items.plan"
JUMP_PLAN = DATA / "payload-place-do-jump.plan"


def feature(site_id, kind, geom_local):
    return {
        "type": "Feature",
        "properties": {"site_id": site_id, "kind": kind, "name": site_id.split("/")[0]},
        "geometry": shapely.geometry.mapping(FRAME.geom_to_wgs84(geom_local)),
    }


def fence_file(tmp_path, keep_in=False):
    feats = [
        feature("prison/1", "keep_out", shapely.box(-20, -300, 20, 300)),
        feature("mast/4", "keep_out", shapely.Point(-200, 0).buffer(15)),
    ]
    if keep_in:
        feats.append(feature("area/9", "keep_in", shapely.box(-500, -500, 500, 500)))
    path = tmp_path / ("fences-in.geojson" if keep_in else "fences.geojson")
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def xy(w):
    """A waypoint's position in the scene, metres rounded to 1."""
    x, y = FRAME.to_local(w.lon, w.lat)
    return round(float(x)), round(float(y))


def legs_of(waypoints):
    return {(a.label, b.label) for a, b in zip(waypoints, waypoints[1:])}


def one_error(capsys):
    lines = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(lines) == 1, lines
    return lines[0]


# ------------------------------------------------------------------ 5: older plan layouts


def test_old_item_form_is_read_as_qgroundcontrol_reads_it():
    # MissionItem::_convertJsonV2ToV3: "coordinate" [lat, lon, alt] becomes params 5-7
    doc = json.loads(OLD_PLAN.read_text())
    waypoints = read_mission(OLD_PLAN)
    assert [w.label for w in waypoints] == [
        "home",
        "item 1 (takeoff)",
        "item 2 (waypoint)",
        "item 3 (waypoint)",
        "item 4 (RTL) -> home",
    ]
    for w, it in zip(waypoints[1:4], doc["mission"]["items"]):
        assert (w.lat, w.lon) == tuple(it["coordinate"][:2])
    assert [xy(w) for w in waypoints] == [(-200, 0), (-200, 0), (-200, 200), (200, 200), (-200, 0)]


def test_check_mission_reads_the_old_plan_and_finds_its_crossing(tmp_path, capsys):
    code = main(["check-mission", str(OLD_PLAN), "--fences", str(fence_file(tmp_path))])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "CROSSES" in out and "prison/1" in out and "item 3 (waypoint)" in out


def test_version_1_geofence_is_its_inclusion_polygon_and_breach_return():
    # GeoFenceController (QGC 3.2): version 1 saves one polygon ("polygon": [[lat, lon], ...],
    # QGCMapPolygon::saveToJson) and breachReturn [lat, lon] without an altitude
    doc = json.loads(OLD_PLAN.read_text())["geoFence"]
    fence = read_plan_geofence(OLD_PLAN)
    assert fence.version == 1
    assert [(i.lat, i.lon) for i in fence.items] == [tuple(p) for p in doc["polygon"]]
    assert {(i.command, i.param1) for i in fence.items} == {(POLYGON_INCLUSION, 4.0)}
    lat, lon = doc["breachReturn"]
    assert fence.return_point == (lon, lat)
    assert fence.upload_items[0] == FenceItem(RETURN_POINT, 0.0, lon, lat)
    assert fence.upload_items[1:] == fence.items == read_plan_fence(OLD_PLAN)


def test_version_2_geofence_keeps_its_breach_return():
    doc = json.loads(JUMP_PLAN.read_text())["geoFence"]
    fence = read_plan_geofence(JUMP_PLAN)
    lat, lon, _alt = doc["breachReturn"]
    assert fence.version == 2 and fence.return_point == (lon, lat)
    assert [i.command for i in fence.upload_items] == [RETURN_POINT] + [POLYGON_INCLUSION] * 4 + [
        CIRCLE_EXCLUSION
    ]


@pytest.mark.parametrize(
    "fence, says",
    [
        ({"version": 3, "polygons": [], "circles": []}, "geoFence version 3"),
        ({"version": "2", "polygons": []}, "geoFence version '2'"),
        ({"version": 1, "polygon": [[35.88, 14.45], [35.89, 14.45]]}, "at least 3 vertices"),
        ({"version": 1, "polygon": [], "breachReturn": [35.88]}, "breachReturn"),
    ],
)
def test_geofence_layouts_it_cannot_read_are_one_line(tmp_path, capsys, fence, says):
    plan = tmp_path / "f.plan"
    plan.write_text(json.dumps({"fileType": "Plan", "geoFence": fence, "version": 1}))
    assert main(["upload", str(plan), "--dry-run", "--allow-unsigned"]) == 2
    err = one_error(capsys)
    assert "f.plan" in err and says in err, err


@pytest.mark.parametrize(
    "fence", [{"version": 1, "polygon": []}, {"version": 2, "polygons": [], "circles": []}]
)
def test_a_plan_without_a_fence_is_not_uploaded(tmp_path, capsys, fence):
    # uploading it would replace the vehicle's fence with none
    plan = tmp_path / "f.plan"
    plan.write_text(json.dumps({"fileType": "Plan", "geoFence": fence, "version": 1}))
    assert main(["upload", str(plan), "--dry-run", "--allow-unsigned"]) == 2
    assert "no polygon or circle" in one_error(capsys)


# ------------------------------------------------------------------ 6: dry runs that check


@pytest.mark.parametrize("name", ["fence-76-items.plan", "fence-76-items.waypoints"])
def test_dry_run_checks_the_items_against_the_profile(capsys, name):
    path = str(DATA / name)
    base = ["upload", path, "--dry-run", "--allow-unsigned"]
    assert main(base) == 2
    err = one_error(capsys)
    assert name in err and "76 fence items" in err and "copter" in err and "70 items" in err
    assert main([*base, "--profile", "plane"]) == 0
    out = capsys.readouterr().out
    assert "76 items" in out and "of 672 bytes (plane)" in out and "nothing sent" in out
    assert main([*base, "--profile", "plane", "--items", "75"]) == 2
    assert "at most 75 items" in one_error(capsys)


def test_dry_run_checks_the_bytes_as_ardupilot_stores_them(tmp_path, capsys):
    # 45 circles: 45 items (a copter holds 70) but 4 + 45 * 13 + 1 = 590 bytes (it has 560)
    circles = [
        {
            "circle": {"center": [35.88 + k * 1e-4, 14.45], "radius": 20},
            "inclusion": False,
            "version": 1,
        }
        for k in range(45)
    ]
    plan = tmp_path / "c.plan"
    plan.write_text(json.dumps({"geoFence": {"circles": circles, "polygons": [], "version": 2}}))
    assert main(["upload", str(plan), "--dry-run", "--allow-unsigned"]) == 2
    assert "590 bytes" in one_error(capsys)
    assert main(["upload", str(plan), "--dry-run", "--allow-unsigned", "--profile", "rover"]) == 0


def test_dry_run_shows_what_it_would_send(tmp_path, capsys):
    figure = tmp_path / "items.png"
    argv = ["upload", str(OLD_PLAN), "--dry-run", "--allow-unsigned", "--figure", str(figure)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "return point" in out and "inclusion polygon 1" in out and "items 1-4" in out
    assert "5 items, 48 of 560 bytes (copter)" in out  # 4 + 9 + (2 + 4 * 8) + 1
    assert figure.read_bytes().startswith(PNG)


def test_a_refused_dry_run_draws_nothing(tmp_path, capsys):
    figure = tmp_path / "items.png"
    argv = ["upload", str(DATA / "fence-76-items.plan"), "--dry-run", "--allow-unsigned"]
    assert main([*argv, "--figure", str(figure)]) == 2
    assert not figure.exists()


def test_the_breach_return_reaches_the_vehicle(tmp_path, capsys):
    from tests.fake_vehicle import FakeVehicle

    fence = read_plan_geofence(JUMP_PLAN)

    async def run():
        async with FakeVehicle() as fake:
            argv = ["upload", str(JUMP_PLAN), "--connect", fake.url, "--allow-unsigned"]
            code = await asyncio.to_thread(main, [*argv, "--link", "pymavlink"])
            return code, [FenceItem(i.command, i.param1, i.lon, i.lat) for i in fake.fence]

    code, held = asyncio.run(run())
    assert code == 0, capsys.readouterr()
    assert [i.command for i in held] == [i.command for i in fence.upload_items]
    lon, lat = fence.return_point
    assert held[0].command == RETURN_POINT
    assert math.isclose(held[0].lon, lon, abs_tol=1e-7) and math.isclose(
        held[0].lat, lat, abs_tol=1e-7
    )


# ------------------------------------------------------------------ 7: check-mission


def test_payload_place_legs_are_checked(tmp_path, capsys):
    code = main(["check-mission", str(JUMP_PLAN), "--fences", str(fence_file(tmp_path))])
    out = capsys.readouterr().out
    assert code == 1
    rows = [line for line in out.splitlines() if "item 6 (payload place)" in line]
    assert rows and all("prison/1" in r and "CROSSES" in r for r in rows), out


def test_do_jump_is_followed_in_a_plan():
    # DO_JUMP's param1 in a plan is the target's doJumpId (MissionController fixes it up on load)
    waypoints = read_mission(JUMP_PLAN)
    legs = legs_of(waypoints)
    assert ("item 4 (waypoint)", "item 2 (waypoint)") in legs  # the jump back, once (repeat 1)
    assert ("item 4 (waypoint)", "item 6 (payload place)") in legs  # then on
    labels = [w.label for w in waypoints]
    assert labels.count("item 2 (waypoint)") == 2 and labels[-1] == "item 7 (RTL) -> home"


def test_the_jump_back_is_checked(tmp_path, capsys):
    assert main(["check-mission", str(JUMP_PLAN), "--fences", str(fence_file(tmp_path))]) == 1
    rows = [line for line in capsys.readouterr().out.splitlines() if "mast/4" in line]
    assert len(rows) == 1 and "item 4 (waypoint)" in rows[0] and "item 2 (waypoint)" in rows[0]


def test_a_jump_forever_ends_and_what_follows_it_is_never_flown(tmp_path, capsys):
    waypoints = read_mission(DATA / "jump-forever.waypoints")
    assert legs_of(waypoints) == {
        ("home", "seq 2 (waypoint)"),
        ("seq 2 (waypoint)", "seq 3 (waypoint)"),
        ("seq 3 (waypoint)", "seq 2 (waypoint)"),  # the inner loop, 5 times
        ("seq 3 (waypoint)", "seq 5 (waypoint)"),
        ("seq 5 (waypoint)", "seq 2 (waypoint)"),  # the outer loop, forever
    }
    assert not any(w.label.startswith(("seq 7", "seq 8")) for w in waypoints)
    code = main(
        [
            "check-mission",
            str(DATA / "jump-forever.waypoints"),
            "--fences",
            str(fence_file(tmp_path)),
        ]
    )
    out = capsys.readouterr().out
    assert code == 1 and "mast/4" in out
    assert "5 legs:" in out  # each leg once, however often it is flown


@pytest.mark.parametrize(
    "rows, says",
    [
        ([(2, 0, 0, 177, 9, 1)], "DO_JUMP to seq 9: no such item"),
        ([(2, 0, 0, 177, 0, 1)], "DO_JUMP to seq 0"),
        ([(2, 0, 0, 601, 4, 1)], "DO_JUMP_TAG to tag 4: no JUMP_TAG"),
    ],
)
def test_a_jump_nowhere_is_one_line(tmp_path, capsys, rows, says):
    lines = [
        "QGC WPL 110",
        "0\t1\t0\t16\t0\t0\t0\t0\t35.88\t14.45\t0\t1",
        "1\t0\t3\t16\t0\t0\t0\t0\t35.881\t14.45\t30\t1",
    ]
    lines += [
        f"{s}\t{c}\t{f}\t{cmd}\t{p1}\t{p2}\t0\t0\t0\t0\t0\t1" for s, c, f, cmd, p1, p2 in rows
    ]
    path = tmp_path / "m.waypoints"
    path.write_text("\n".join(lines) + "\n")
    assert main(["check-mission", str(path), "--fences", str(fence_file(tmp_path))]) == 2
    err = one_error(capsys)
    assert "m.waypoints" in err and "line 4" in err and says in err, err


def test_a_plan_jump_to_a_missing_doJumpId_is_one_line(tmp_path, capsys):
    doc = json.loads(JUMP_PLAN.read_text())
    doc["mission"]["items"][4]["params"][0] = 42
    path = tmp_path / "j.plan"
    path.write_text(json.dumps(doc))
    assert main(["check-mission", str(path), "--fences", str(fence_file(tmp_path))]) == 2
    assert "item 5: DO_JUMP to doJumpId 42: no such item" in one_error(capsys)


def test_leaving_the_keep_in_fence_is_not_clear(tmp_path, capsys):
    path = DATA / "leaves-keep-in.waypoints"
    assert main(["check-mission", str(path), "--fences", str(fence_file(tmp_path))]) == 0
    capsys.readouterr()
    code = main(["check-mission", str(path), "--fences", str(fence_file(tmp_path, keep_in=True))])
    out = capsys.readouterr().out
    assert code == 1
    rows = [line for line in out.splitlines() if "area/9" in line]
    assert len(rows) == 2 and all("LEAVES" in r for r in rows), out  # out to (-700, 400), back
    assert "2 leave a keep-in fence" in out


def test_a_mission_inside_the_keep_in_fence_near_its_edge(tmp_path, capsys):
    # the old plan flies within the operating area, 300 m from its edge at the closest: clear
    # of it; with a clearance of 350 m the legs near the edge graze it
    fences = str(fence_file(tmp_path, keep_in=True))
    main(["check-mission", str(OLD_PLAN), "--fences", fences])
    out = capsys.readouterr().out
    assert "area/9" not in out and "0 leave a keep-in fence" in out
    main(["check-mission", str(OLD_PLAN), "--fences", fences, "--clearance", "350"])
    rows = [line for line in capsys.readouterr().out.splitlines() if "area/9" in line]
    assert rows and all("near its edge" in r for r in rows)


def test_waypoint_fence_files_still_carry_their_return_point():
    items = read_waypoints_fence(DATA / "fence-76-items.waypoints")
    assert items[0].command == RETURN_POINT and len(items) == 76


def test_a_jump_repeated_a_billion_times_is_bounded_and_then_passed(tmp_path):
    # the loop's legs are all flown once it has gone round; after MAX_POSITIONS positions
    # the jump is passed, so what follows it is still checked
    from alphafence.flights.mission import MAX_POSITIONS

    text = (
        (DATA / "jump-forever.waypoints")
        .read_text()
        .replace("\t2.000000\t-1.000000\t", "\t2.000000\t1000000000.000000\t")
    )
    path = tmp_path / "billion.waypoints"
    path.write_text(text)
    waypoints = read_mission(path)
    assert MAX_POSITIONS <= len(waypoints) < MAX_POSITIONS + 10
    legs = legs_of(waypoints)
    assert ("seq 5 (waypoint)", "seq 7 (waypoint)") in legs  # passed at last
    assert ("seq 7 (waypoint)", "seq 8 (RTL) -> home") in legs and len(legs) == 7


def test_a_downloaded_fence_written_as_a_plan_keeps_its_return_point(tmp_path):
    # download writes what the vehicle holds: its return point item becomes the breachReturn
    from alphafence.fencefiles import qgc_plan

    held = read_waypoints_fence(DATA / "fence-76-items.waypoints")
    path = tmp_path / "downloaded.plan"
    path.write_text(qgc_plan.dumps(qgc_plan.plan_document(held)))
    assert read_plan_geofence(path).upload_items == held


def test_a_compiled_upload_draws_its_items_too(tmp_path, capsys):
    figure = tmp_path / "compiled.png"
    argv = ["upload", str(fence_file(tmp_path)), "--bbox=14.44,35.87,14.46,35.89", "--dry-run"]
    assert main([*argv, "--allow-unsigned", "--figure", str(figure)]) == 0
    assert figure.read_bytes().startswith(PNG) and "nothing sent" in capsys.readouterr().out
