"""check-mission at the legs' altitudes: each leg against each fence's band in the band's own
reference (above home, AMSL placed by the mission's home altitude, AGL; terrain-relative legs
with AGL limits only), altitudes interpolated along climbing legs, RTL at its altitude, and
what cannot be compared counted against the leg with a note.

The samples are written as QGroundControl writes plans (``QJsonDocument`` indented by 4, keys
sorted; a Survey complex item holding its transects as SimpleItems) and as ArduPilot/MAVProxy
write QGC WPL 110 files, in a synthetic scene (metres east/north of 14.45 E, 35.88 N; home at
the origin, 85 m AMSL):

* ``survey-50m.plan``: takeoff to 50 m above home, three transects at 50 m across x = 100..500
  m (y = -60, 0, 60; the last ends at (500, 60)), RTL;
* ``climb-over-zones.waypoints``: takeoff to 30 m, (-300, 0) at 30 m, then a straight climb to
  (700, 0) at 150 m, RTL.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.cli import main
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.flights.mission import load_mission
from alphafence.geo.frame import LocalFrame
from alphafence.review.mission_check import check_mission

DATA = Path(__file__).parent / "data" / "qgc"
SURVEY = DATA / "survey-50m.plan"
CLIMB = DATA / "climb-over-zones.waypoints"
FRAME = LocalFrame(14.45, 35.88)
TOWER = shapely.box(200, -100, 400, 100)  # under the survey's three transects
LOW, HIGH = shapely.box(0, -100, 200, 100), shapely.box(500, -100, 600, 100)  # under the climb


def feature(site_id, kind, geom, lo=None, hi=None, ref=None):
    props = {"site_id": site_id, "kind": kind, "alt_min_m": lo, "alt_max_m": hi}
    if ref:
        props.update(lower_reference=ref, upper_reference=ref)
    geometry = shapely.geometry.mapping(FRAME.geom_to_wgs84(geom))
    return {"type": "Feature", "properties": props, "geometry": geometry}


def fences(tmp_path, *feats, name="fences.geojson"):
    path = tmp_path / name
    path.write_text(json.dumps({"type": "FeatureCollection", "features": list(feats)}))
    return path


def items_of(doc):
    """Every SimpleItem of a plan, those inside complex items included."""
    for it in doc["mission"]["items"]:
        inner = it.get("TransectStyleComplexItem", {}).get("Items")
        yield from inner if inner is not None else [it]


def survey_copy(tmp_path, alt=None, frame=None, home_alt=None):
    """The survey plan with its positions at ``alt``, in ``frame``, or home at ``home_alt``."""
    doc = json.loads(SURVEY.read_text())
    for it in items_of(doc):
        if it["frame"] == 3 and frame is not None:
            it["frame"] = frame
        if it["command"] in (16, 22) and alt is not None:
            it["params"][6] = alt
    if home_alt is not None:
        doc["mission"]["plannedHomePosition"][2] = home_alt
    path = tmp_path / "survey-copy.plan"
    path.write_text(json.dumps(doc, indent=4, sort_keys=True))
    return path


def climb_copy(tmp_path, home_alt):
    lines = CLIMB.read_text().splitlines()
    row = lines[1].split("\t")
    row[10] = f"{home_alt:.6f}"
    lines[1] = "\t".join(row)
    path = tmp_path / "climb-copy.waypoints"
    path.write_text("\n".join(lines) + "\n")
    return path


def run(capsys, mission, fence_file, *extra):
    code = main(["check-mission", str(mission), "--fences", str(fence_file), *extra])
    out, err = capsys.readouterr()
    return code, out, err


def fenced_legs(mission, fence_file, clearance=20.0):
    """``{(leg number, fence): (distance m, crosses)}`` from the library."""
    result = check_mission(mission, read_fence_file(fence_file), clearance)
    return {(i.leg, i.fence): (i.distance_m, i.crosses) for i in result.issues}, result


def transect_legs(mission):
    """The numbers of the legs flown along the three transects (west-east or east-west)."""
    legs = check_mission(mission, []).legs
    out = []
    for n, a, b in legs:
        (xa, ya), (xb, yb) = (FRAME.to_local(w.lon, w.lat) for w in (a, b))
        if abs(float(ya - yb)) < 1 and abs(float(xa - xb)) > 300:
            out.append(n)
    return out


# ------------------------------------------------------------------ the survey and its floor


def test_the_samples_read_with_their_altitudes():
    survey = load_mission(SURVEY)
    assert survey.home_amsl == 85.0
    assert len(transect_legs(SURVEY)) == 3
    assert {w.alt for w in survey.waypoints[1:-1]} == {50.0}
    assert {w.frame for w in survey.waypoints} == {"home"}
    climb = load_mission(CLIMB)
    assert climb.home_amsl == 85.0
    # takeoff without a position: the climb to 30 m is flown at home, before the first leg
    assert climb.waypoints[1].profile == ((0.0, 0.0), (0.0, 30.0), (1.0, 30.0))
    assert climb.waypoints[2].profile == ((0.0, 30.0), (1.0, 150.0))
    # RTL: home at the larger of 150 m and RTL_ALT, then down
    assert climb.waypoints[3].profile == ((0.0, 150.0), (1.0, 150.0), (1.0, 0.0))


def test_a_survey_under_a_zones_floor_passes(tmp_path, capsys):
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 120.0, None, "AGL"))
    code, out, err = run(capsys, SURVEY, zone)
    assert code == 0, out
    assert "tower/1" not in out and "0 cross a keep-out fence, 0 graze one" in out
    # the same zone from the ground up: every transect and the way home cross it
    ground = fences(tmp_path, feature("tower/1", "keep_out", TOWER), name="ground.geojson")
    code, out, _ = run(capsys, SURVEY, ground)
    assert code == 1 and "4 cross a keep-out fence" in out


def test_a_survey_over_a_zones_floor_is_reported(tmp_path, capsys):
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 40.0, None, "AGL"))
    code, out, _ = run(capsys, SURVEY, zone)
    assert code == 1 and "CROSSES" in out
    hits, _ = fenced_legs(SURVEY, zone)
    crossing = {leg for (leg, fence), (_, crosses) in hits.items() if crosses}
    assert set(transect_legs(SURVEY)) <= crossing
    # the survey raised to 150 m over a floor of 120 m
    high = survey_copy(tmp_path, alt=150)
    floor = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 120.0, None, "AGL"))
    code, out, _ = run(capsys, high, floor)
    assert code == 1 and "tower/1" in out


def test_a_leg_just_under_the_floor_grazes_it(tmp_path, capsys):
    # 10 m under a floor at 60 m: within the clearance vertically, straight over the zone
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 60.0, None, "AGL"))
    hits, _ = fenced_legs(SURVEY, zone)
    for leg in transect_legs(SURVEY):
        distance, crosses = hits[(leg, "tower/1")]
        assert not crosses and distance == pytest.approx(10.0, abs=1e-3)
    code, out, _ = run(capsys, SURVEY, zone)
    assert code == 0 and "grazes" in out


# ------------------------------------------------------------------ a climbing leg


def test_a_climbing_leg_crosses_a_floor_only_where_it_is_above_it(tmp_path, capsys):
    # leg 2 climbs from 30 m at x = -300 to 150 m at x = 700: over LOW (x 0..200) at 66-90 m,
    # over HIGH (x 500..600) at 126-138 m; both floors at 120 m
    zones = fences(
        tmp_path,
        feature("low/1", "keep_out", LOW, 120.0, None, "AGL"),
        feature("high/2", "keep_out", HIGH, 120.0, None, "AGL"),
    )
    hits, _ = fenced_legs(CLIMB, zones)
    assert hits[(2, "high/2")] == (0.0, True)
    assert (2, "low/1") not in hits
    code, out, _ = run(capsys, CLIMB, zones)
    rows = [line for line in out.splitlines() if "seq 3 (waypoint)" in line and "RTL" not in line]
    assert code == 1 and any("high/2" in r and "CROSSES" in r for r in rows), out
    assert not any("low/1" in r for r in rows), out
    # with a clearance of 30 m it grazes LOW: where the part of the leg within m of the
    # floor comes within m of the zone's east edge (x = 200); the leg rises 120 m in 1000 m
    slope, floor = 120.0 / 1000.0, 120.0
    x_at = -300.0 + (floor - 30.0) / slope  # where the leg reaches the floor
    expected = (x_at - 200.0) / (1.0 + 1.0 / slope)  # x_at - m / slope - 200 = m
    hits, _ = fenced_legs(CLIMB, zones, clearance=30.0)
    distance, crosses = hits[(2, "low/1")]
    assert not crosses and distance == pytest.approx(expected, abs=1e-3)


def test_a_climbing_legs_high_part_beside_the_zone_is_clear(tmp_path):
    # HIGH moved 150 m north of the leg: the high part passes beside it, not over it
    beside = fences(
        tmp_path, feature("high/2", "keep_out", shapely.box(500, 150, 600, 250), 120, None, "AGL")
    )
    hits, _ = fenced_legs(CLIMB, beside)
    assert (2, "high/2") not in hits


# ------------------------------------------------------------------ AMSL bands and home


def test_an_amsl_floor_is_placed_by_the_plans_home_altitude(tmp_path, capsys):
    # a floor at 200 m AMSL: 115 m above a home at 85 m AMSL (the plan's), 40 m above one at
    # 160 m; the survey flies at 50 m above home
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 200.0, None, "AMSL"))
    code, out, err = run(capsys, SURVEY, zone)
    assert code == 0 and "tower/1" not in out, out
    assert "note:" not in err  # nothing approximated, nothing counted conservatively
    code, out, _ = run(capsys, survey_copy(tmp_path, home_alt=160), zone)
    assert code == 1 and "tower/1" in out and "CROSSES" in out


def test_an_unknown_home_altitude_counts_an_amsl_band_at_every_altitude(tmp_path, capsys):
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 200.0, None, "AMSL"))
    code, out, err = run(capsys, survey_copy(tmp_path, home_alt=0), zone)
    assert code == 1 and "CROSSES" in out
    said = " ".join(err.split())  # the console wraps long notes
    assert said.count("note:") == 1 and "note: home's altitude AMSL is not known" in said, err


def test_a_waypoint_files_line_0_is_homes_altitude(tmp_path):
    # HIGH's floor at 200 m AMSL; leg 2 passes over it at 126-138 m above home
    zone = fences(tmp_path, feature("high/2", "keep_out", HIGH, 200.0, None, "AMSL"))
    hits, _ = fenced_legs(CLIMB, zone)  # home at 85 m AMSL: 211-223 m AMSL
    assert hits[(2, "high/2")][1]
    hits, _ = fenced_legs(climb_copy(tmp_path, 30.0), zone)  # home at 30 m: 156-168 m AMSL
    assert (2, "high/2") not in hits


def test_amsl_frame_items_are_taken_above_home(tmp_path):
    # the survey in MAV_FRAME_GLOBAL at 135 m AMSL is 50 m above the home at 85 m AMSL
    plan = survey_copy(tmp_path, alt=135, frame=0)
    assert {w.alt for w in load_mission(plan).waypoints[2:-1]} == {50.0}
    floor = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 120.0, None, "AGL"))
    hits, result = fenced_legs(plan, floor)
    assert not hits and not any("not known" in n for n in result.notes)


# ------------------------------------------------------------------ terrain frame


def test_terrain_legs_are_counted_within_amsl_bands_with_a_note(tmp_path, capsys):
    plan = survey_copy(tmp_path, frame=10)  # MAV_FRAME_GLOBAL_TERRAIN_ALT, 50 m
    amsl = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 200.0, None, "AMSL"))
    code, out, err = run(capsys, plan, amsl)
    assert code == 1 and "CROSSES" in out and "terrain" in out
    said = " ".join(err.split())  # the console wraps long notes
    assert said.count("fly above the terrain") == 1, err
    assert "fly above the terrain (no terrain data here): compared with AGL limits only" in said
    # an AGL floor is compared with the height above the terrain: 50 m under 120 m is clear;
    # RTL from a height above the terrain climbs to a height above home not known here: its
    # way home over the tower counts within the band
    agl = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 120.0, None, "AGL"))
    hits, result = fenced_legs(plan, agl)
    rtl = result.legs[-1][0]
    assert result.legs[-1][2].label.endswith("(RTL) -> home")
    assert set(hits) == {(rtl, "tower/1")}
    assert any("above the terrain" in n for n in result.notes)
    assert any(f"{rtl}: altitude not known" in n for n in result.notes)


# ------------------------------------------------------------------ keep-in bands, RTL


def test_a_keep_in_fences_ceiling_is_left_above_it(tmp_path, capsys):
    area = fences(
        tmp_path,
        feature("area/9", "keep_in", shapely.box(-2000, -2000, 2000, 2000), None, 100.0, "AGL"),
    )
    code, out, _ = run(capsys, SURVEY, area)
    assert code == 0 and "0 leave a keep-in fence" in out
    code, out, _ = run(capsys, survey_copy(tmp_path, alt=150), area)
    assert code == 1 and "LEAVES" in out


def test_rtl_flies_home_at_rtl_alt(tmp_path, capsys):
    # the way home from (500, 60) passes over the tower; its floor is 80 m
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 80.0, None, "AGL"))
    code, out, _ = run(capsys, SURVEY, zone)
    assert code == 0 and "tower/1" not in out
    code, out, _ = run(capsys, SURVEY, zone, "--rtl-alt", "100")
    rows = [line for line in out.splitlines() if "(RTL) -> home" in line]
    assert code == 1 and len(rows) == 1 and "CROSSES" in rows[0] and "50-0 ^100" in rows[0]


def test_climbs_and_landings_where_the_vehicle_is_are_checked_and_loops_end(tmp_path, capsys):
    # takeoff to 30 m and land, both at the current position, jumped back to for ever
    lat, lon = 35.88, 14.45
    lines = [
        "QGC WPL 110",
        f"0\t1\t0\t16\t0\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t85.000000\t1",
        "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t30.000000\t1",
        "2\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0.000000\t1",
        "3\t0\t0\t177\t1\t-1\t0\t0\t0\t0\t0.000000\t1",
    ]
    path = tmp_path / "hop.waypoints"
    path.write_text("\n".join(lines) + "\n")
    waypoints = load_mission(path).waypoints
    assert [w.label for w in waypoints] == ["home", "seq 2 (land)"]
    assert max(z for _, z in waypoints[1].profile) == 30.0
    over_home = shapely.box(-50, -50, 50, 50)
    low = fences(tmp_path, feature("roof/1", "keep_out", over_home, 20.0, None, "AGL"))
    code, out, _ = run(capsys, path, low)
    assert code == 1 and "roof/1" in out
    high = fences(tmp_path, feature("roof/1", "keep_out", over_home, 60.0, None, "AGL"))
    assert run(capsys, path, high)[0] == 0


def test_no_empty_note_for_plain_amsl_limits(tmp_path, capsys):
    record = read_fence_file(
        fences(tmp_path, feature("tower/1", "keep_out", TOWER, 200.0, None, "AMSL"))
    )
    assert FenceSet(record).altitude_notes() == []
    zone = fences(tmp_path, feature("tower/1", "keep_out", TOWER, 200.0, None, "AMSL"))
    _, _, err = run(capsys, SURVEY, zone)
    assert not re.search(r"note:\s*$", err, re.M), err
