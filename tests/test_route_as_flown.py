"""Routes and mission legs as ArduPilot flies them: a leg between two waypoints is a straight
line in lon/lat, which in metres bows toward the equator from the straight line between its
ends (about L**2 * tan(lat) / (8 R): 100 m for a 50 km leg at 64° N).

Every check here owes nothing to the kit's frames: legs are sampled along their lon/lat lines
(waypoints as ArduPilot holds them, 1e-7 degrees), and tests/ardupilot_model.py measures each
sample's geodesic distance (pyproj Geod, WGS84) to the fences' lon/lat edges and whether
ArduPilot would call it inside a fence.

Scenes are in metres east/north of a frame's origin at 62-64° N (the frame serves only to
place the fences and ends).
"""

import json

import numpy as np
import pytest
import shapely
from pyproj import Geod

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import dumps, mission_items, plan_document
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.reroute import Rerouter
from alphafence.review.mission_check import check_mission
from alphafence.route.roadmap import Roadmap
from tests.ardupilot_model import boundary_samples, clearance, e7, polygon_outside
from tests.test_route_corridor import (
    COUNTRY,
    GOAL_XY,
    START_XY,
    cli_position,
    lonlat,
    national_fences,
    write_fences,
)

CLEARANCE = 20.0
GEOD = Geod(ellps="WGS84")
SPACING_M = 0.5  # samples along a leg: the least distance is overstated by under 2 mm


def box(frame, x0, y0, x1, y1):
    """A keep-out fence: the metric box's corners as lon/lat vertices."""
    return frame.geom_to_wgs84(shapely.box(x0, y0, x1, y1))


def as_held(path_lonlat):
    """Waypoints as ArduPilot holds them: 1e-7 degree integers."""
    return e7(path_lonlat) * 1e-7


def line_in_fences(line, rings, spacing_m=SPACING_M):
    """(samples along a lon/lat line ArduPilot would call inside one of the keep-out fences
    ``rings``, least geodesic distance from a sample to their lon/lat edges)."""
    lon, lat = boundary_samples(line, spacing_m)
    inside = sum(int((~polygon_outside(lat, lon, r[:, 1], r[:, 0])).sum()) for r in rings)
    return inside, clearance(line, rings, spacing_m, CLEARANCE)[1]


def flown_clearance(path_lonlat, fences):
    """(samples ArduPilot would call inside a fence, least geodesic distance from a sample to
    a fence's edges) over every leg of the path, each flown along its lon/lat line."""
    rings = [np.asarray(p.exterior.coords)[:-1] for f in fences for p in shapely.get_parts(f)]
    inside, least = 0, np.inf
    path = as_held(np.asarray(path_lonlat, float))
    for a, b in zip(path[:-1], path[1:]):
        leg_inside, leg_least = line_in_fences(shapely.LineString([a, b]), rings)
        inside += leg_inside
        least = min(least, leg_least)
    return inside, least


def plan_path(path):
    """The waypoints a QGroundControl plan flies through, (lon, lat), the takeoff's first."""
    items = json.loads(path.read_text())["mission"]["items"]
    return np.array([(it["params"][5], it["params"][4]) for it in items if it["command"] != 20])


def north_scenes():
    """(frame, start, goal, fences): 80 km east at 64° N past fences 25-40 m south of the
    straight line (its lon/lat line bows 250 m south, across them); and 100 km east at 62° N
    through a 100 m gap in an 80 km wall, on legs of 20-50 km that pass 40 m north of a fence
    half way to the gap and half way on (lon/lat lines of 49 km bow 88 m south)."""
    at64 = LocalFrame(10.5, 64.0)
    past = [
        box(at64, -22e3, -2e3, -18e3, -40.0),
        box(at64, 13e3, -1e3, 17e3, -25.0),
        box(at64, -2e3, 60.0, 2e3, 2e3),  # north of the line: the lon/lat line bows away
    ]
    at62 = LocalFrame(25.0, 62.0)
    gap = [
        box(at62, -1e3, -40e3, 1e3, 3000.0),
        box(at62, -1e3, 3100.0, 1e3, 40e3),
        box(at62, -26e3, -2e3, -25e3, 1470.0),
        box(at62, 25e3, -2e3, 26e3, 1470.0),
    ]
    return [
        (at64, lonlat(at64, -40e3, 0.0), lonlat(at64, 40e3, 0.0), past),
        (at62, lonlat(at62, -50e3, 0.0), lonlat(at62, 50e3, 0.0), gap),
    ]


@pytest.mark.parametrize("scene", north_scenes(), ids=["past-at-64N", "gap-at-62N"])
def test_a_long_route_far_north_keeps_the_clearance_as_flown(tmp_path, capsys, scene):
    frame, start, goal, geoms = scene
    records = [FenceRecord(f"site/{i}", "keep_out", g) for i, g in enumerate(geoms)]
    fences = write_fences(tmp_path / "north.geojson", records)
    plan = tmp_path / "north.plan"
    args = ["route", str(fences), "--from", cli_position(start), "--to", cli_position(goal)]
    assert main([*args, "-o", str(plan)]) == 0
    out = capsys.readouterr().out
    path = plan_path(plan)
    half = path[: (len(path) + 1) // 2]  # the way out (the mission flies it back)
    assert np.allclose(half[0], start) and np.allclose(half[-1], goal)
    # legs of tens of kilometres, far north: their lon/lat lines bow tens of metres or more
    _, _, legs = GEOD.inv(half[:-1, 0], half[:-1, 1], half[1:, 0], half[1:, 1])
    assert legs.max() > 19e3, legs
    inside, least = flown_clearance(half, geoms)
    assert inside == 0 and least >= CLEARANCE, (inside, least)
    assert "waypoints added along long legs" in out  # the user is told why there are more
    # and check-mission, which checks legs as flown, finds nothing to report
    assert main(["check-mission", str(plan), "--fences", str(fences)]) == 0, capsys.readouterr()


def mission_past_a_corner(tmp_path):
    """At 64° N: a 50 km leg east whose ends' straight line passes 50 m north of a fence's
    north-east corner, half way along; the fence's edges run along a parallel and a
    meridian. Returns (plan, fences file, the leg's ends, the fence)."""
    frame = LocalFrame(10.5, 64.0)
    a, b = lonlat(frame, -25e3, 0.0), lonlat(frame, 25e3, 0.0)
    corner = lonlat(frame, 0.0, -50.0)
    fence = shapely.box(corner[0] - 0.05, corner[1] - 0.02, corner[0], corner[1])
    path = tmp_path / "corner.plan"
    items = mission_items(np.array([a, b]), 60.0, fly_back=False)
    path.write_text(dumps(plan_document([], a, items)))
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"site_id": "prison/way/64", "kind": "keep_out"},
                "geometry": shapely.geometry.mapping(fence),
            }
        ],
    }
    fences = tmp_path / "corner.geojson"
    fences.write_text(json.dumps(doc))
    return path, fences, (a, b), fence


def test_check_mission_finds_a_long_leg_whose_lon_lat_line_cuts_a_fence_corner(tmp_path, capsys):
    plan, fences, (a, b), fence = mission_past_a_corner(tmp_path)
    ring = np.asarray(fence.exterior.coords)[:-1]
    # the shortest line between the leg's ends (the geodesic, in 2 km steps) clears the corner
    mid = GEOD.npts(*a, *b, 24)
    geodesic = shapely.LineString([a, *mid, b])
    inside, least = line_in_fences(geodesic, [ring], 1.0)
    assert inside == 0 and least > 2 * CLEARANCE, least
    # ArduPilot flies the leg along its lon/lat line, into the fence
    assert line_in_fences(shapely.LineString([a, b]), [ring], 1.0)[0] > 0
    result = check_mission(plan, [FenceRecord("prison/way/64", "keep_out", fence)], CLEARANCE)
    crossing = [(i.start, i.end) for i in result.issues if i.crosses]
    assert crossing == [
        ("item 1 (takeoff)", "item 2 (waypoint)"),
        ("item 2 (waypoint)", "item 3 (RTL) -> home"),  # RTL flies the same line back
    ], result.issues
    capsys.readouterr()
    assert main(["check-mission", str(plan), "--fences", str(fences)]) == 1
    out = capsys.readouterr().out
    assert "prison/way/64" in out and "CROSSES" in out, out


def test_reroute_over_a_national_file_builds_only_the_corridors_roadmap(monkeypatch):
    records = national_fences()
    keep_out = sum(r.kind == "keep_out" for r in records)
    built = []
    build = Roadmap._build

    def counted(self, bounds):
        built.append(len(self.keep_out))
        # a roadmap over every fence of the file takes minutes (the monitor would wait on it)
        assert len(self.keep_out) <= keep_out // 10, f"a roadmap over {len(self.keep_out)}"
        return build(self, bounds)

    monkeypatch.setattr(Roadmap, "_build", counted)
    rerouter = Rerouter(records, CLEARANCE)
    here, goal = lonlat(COUNTRY, *START_XY), lonlat(COUNTRY, *GOAL_XY)
    d = np.subtract(GOAL_XY, START_XY)
    ve, vn = 10.0 * d / np.hypot(*d)  # flying straight at the goal, the town and bars between
    plan = rerouter.plan(*here, ve, vn, goal, lead_m=30.0)
    assert built and plan.waypoints[-1] == (round(goal[1], 7), round(goal[0], 7))
    flown = np.array([here] + [(lon, lat) for lat, lon in plan.waypoints])
    assert len(flown) > 2  # round the town and the bars
    # the fences near the way (in a frame of the test's own), measured as ArduPilot reads them
    frame = LocalFrame.around_coords(flown)
    x, y = frame.to_local(flown[:, 0], flown[:, 1])
    way = shapely.LineString(np.column_stack([x, y]))
    geoms = np.array([r.geometry for r in records if r.kind == "keep_out"], dtype=object)
    local = frame.geom_to_local(geoms)
    near = geoms[shapely.dwithin(local, way, 2e3) & ~shapely.is_empty(local)]
    assert len(near) >= 3  # the bars at least
    inside, least = flown_clearance(flown, near)
    assert inside == 0 and least >= CLEARANCE, (inside, least)
    assert plan.clearance_m >= CLEARANCE
