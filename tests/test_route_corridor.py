"""Routing over a national fence file: only the fences in a corridor around start and goal go
into the roadmap, the corridor widens when its route comes too close to a fence left out, the
route keeps the clearance from every fence of the file, and Ctrl-C stops the planner at once
with nothing written."""

import json
import os
import re
import selectors
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import shapely
from pyproj import Geod

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.route import CorridorPlanner, NoRoute

CLEARANCE = 20.0
COUNTRY = LocalFrame(2.5, 46.5)  # fences over 800 x 800 km around it
START_XY, GOAL_XY = (-15e3, -5e3), (20e3, 8e3)  # 37 km apart, in COUNTRY's metres
GEOD = Geod(ellps="WGS84")


def lonlat(frame, x, y):
    lon, lat = frame.to_wgs84(x, y)
    return float(lon), float(lat)


def site(rng, x, y, radius):
    """A convex polygon of up to 11 vertices around (x, y), metres."""
    k = int(rng.integers(5, 12))
    a = rng.uniform(0.0, 2.0 * np.pi, k)
    r = radius * rng.uniform(0.6, 1.0, k)
    return shapely.convex_hull(
        shapely.multipoints(np.column_stack([x + r * np.cos(a), y + r * np.sin(a)]))
    )


def national_fences(seed=7):
    """About 800 keep-out fences spread over a country, a town of 60 on the way from start to
    goal, three bars across the straight line; 20 in Australia and one around the antipode
    of the route's midpoint (where a frame centred on the route cannot place it)."""
    rng = np.random.default_rng(seed)
    ends = np.array([START_XY, GOAL_XY])
    shapes = []
    spread = rng.uniform(-400e3, 400e3, size=(800, 2))
    town = rng.normal(np.mean(ends, axis=0), 4e3, size=(60, 2))
    for x, y in np.vstack([spread, town]):
        if np.hypot(*(ends - (x, y)).T).min() > 2.5e3:  # start and goal stay in the open
            shapes.append(site(rng, x, y, rng.uniform(100.0, 1500.0)))
    d = (ends[1] - ends[0]) / np.hypot(*(ends[1] - ends[0]))
    normal = np.array([-d[1], d[0]])
    for t in (0.25, 0.5, 0.75):  # 2 km bars across the line
        c = ends[0] + t * (ends[1] - ends[0])
        a, b = c - 1e3 * normal, c + 1e3 * normal
        shapes.append(shapely.LineString([a, b]).buffer(30.0, cap_style="flat"))
    records = [
        FenceRecord(f"prison/way/{i}", "keep_out", COUNTRY.geom_to_wgs84(g), name=f"site {i}")
        for i, g in enumerate(shapes)
    ]
    australia = LocalFrame(133.0, -25.0)
    for i, (x, y) in enumerate(rng.uniform(-1000e3, 1000e3, size=(20, 2))):
        g = australia.geom_to_wgs84(shapely.Point(x, y).buffer(500.0))
        records.append(FenceRecord(f"aerodrome/way/{i}", "keep_out", g))
    mid = lonlat(COUNTRY, *np.mean(ends, axis=0))
    lon, lat = mid[0] - 180.0, -mid[1]
    antipode = shapely.box(lon - 0.05, lat - 0.05, lon + 0.05, lat + 0.05)
    records.append(FenceRecord("aerodrome/antipode", "keep_out", antipode))
    return records


def write_fences(path, records):
    feats = [
        {
            "type": "Feature",
            "properties": {"site_id": r.site_id, "kind": r.kind, "name": r.name or r.site_id},
            "geometry": shapely.geometry.mapping(r.geometry),
        }
        for r in records
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def cli_position(lon_lat):
    return f"{lon_lat[1]:.8f},{lon_lat[0]:.8f}"  # the command line's LAT,LON


def plan_lonlat(path):
    items = json.loads(path.read_text())["mission"]["items"]
    # takeoff at the start, then a waypoint at every later vertex (--one-way: no way back)
    return np.array([(it["params"][5], it["params"][4]) for it in items if it["command"] != 20])


def clearance_to_all(path_lonlat, records, near_m=1_000e3):
    """Least distance from the path to every keep-out fence within ``near_m`` of its start (in
    a frame of the test's own around the path); every other fence is checked to be farther
    than that on the ellipsoid."""
    lon0, lat0 = path_lonlat[0]
    cx, cy = np.array([r.geometry.centroid.coords[0] for r in records]).T
    _, _, dist = GEOD.inv(np.full(len(cx), lon0), np.full(len(cy), lat0), cx, cy)
    near = dist < near_m
    assert np.all(dist[~near] > 2 * near_m)  # the far ones are on another continent
    frame = LocalFrame.around_coords(path_lonlat)
    fences = frame.geom_to_local(np.array([r.geometry for r in records], dtype=object)[near])
    x, y = frame.to_local(path_lonlat[:, 0], path_lonlat[:, 1])
    xy = np.column_stack([x, y])
    legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    return float(min(shapely.distance(leg, shapely.union_all(fences)) for leg in legs))


def test_a_national_file_routes_over_a_corridor_and_clears_every_fence(tmp_path, capsys):
    records = national_fences()
    fences = write_fences(tmp_path / "national.geojson", records)
    start, goal = lonlat(COUNTRY, *START_XY), lonlat(COUNTRY, *GOAL_XY)
    plan = tmp_path / "m.plan"
    args = ["route", str(fences), "--from", cli_position(start), "--to", cli_position(goal)]
    assert main([*args, "-o", str(plan), "--one-way"]) == 0
    out = capsys.readouterr().out
    # the roadmaps were built from the corridor's fences, a small share of the file's
    counts = [(int(n), int(total)) for n, total in re.findall(r"corridor \d+: (\d+) of (\d+)", out)]
    assert counts, out
    assert all(total > 800 for _, total in counts)
    assert all(0 < n <= total // 10 for n, total in counts), counts
    assert "21 fences more than 5,000 km away are left out" in out  # Australia, the antipode
    path = plan_lonlat(plan)
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert len(path) > 2  # the town and the bars across the line make it turn
    assert clearance_to_all(path, records) >= CLEARANCE


def test_the_roadmap_holds_only_the_corridor_fences():
    records = national_fences()
    start, goal = lonlat(COUNTRY, *START_XY), lonlat(COUNTRY, *GOAL_XY)
    planner = CorridorPlanner(records, start, goal, clearance=CLEARANCE)
    route, path = planner.route()
    last = planner.corridors[-1]
    assert planner.out_of_reach == 21
    assert planner.roadmap.keep_out.size == last.fences.size < len(planner.keep_out) // 10
    # the planner's fences are the file's within reach, and the corridor holds every one
    # within its half-width of the straight line
    line = shapely.LineString([planner.start_xy, planner.goal_xy])
    within = np.flatnonzero(shapely.distance(planner.keep_out, line) <= last.half_width_m)
    assert np.array_equal(within, last.fences)
    assert route.min_clearance_m >= CLEARANCE
    assert clearance_to_all(path, records) >= CLEARANCE


def wall_of_pieces(frame, half_length, piece=1000.0, gap=CLEARANCE):
    """A wall along x = 0 from -half_length to +half_length metres, of 40 m thick pieces with
    gaps narrower than twice the clearance: closed to a route, however it is cut."""
    ys = np.arange(-half_length, half_length, piece + gap)
    boxes = [shapely.box(-20.0, y, 20.0, y + piece) for y in ys]
    records = [
        FenceRecord(f"wall/{i}", "keep_out", frame.geom_to_wgs84(b)) for i, b in enumerate(boxes)
    ]
    return records, boxes


def test_the_corridor_widens_when_its_route_meets_a_fence_left_out():
    frame = LocalFrame(10.0, 50.0)
    records, boxes = wall_of_pieces(frame, 20e3)
    start, goal = lonlat(frame, -1000.0, 1.0), lonlat(frame, 1000.0, -1.0)
    planner = CorridorPlanner(records, start, goal, clearance=CLEARANCE)
    route, path = planner.route()
    first, last = planner.corridors[0], planner.corridors[-1]
    # the first corridor held a few pieces of the wall; its route slipped between the last of
    # them and the next, left out
    assert 0 < first.fences.size < len(boxes) and first.outside > 0
    assert len(planner.corridors) >= 2 and last.outside == 0
    widths = [c.half_width_m for c in planner.corridors]
    assert all(b >= 2 * a for a, b in zip(widths, widths[1:]))
    assert last.fences.size > first.fences.size
    # round the end of the wall, clear of every piece
    x, y = frame.to_local(path[:, 0], path[:, 1])
    xy = np.column_stack([x, y])
    legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    assert np.abs(xy[:, 1]).max() > 20e3
    assert shapely.distance(legs[:, None], np.array(boxes)[None, :]).min() >= CLEARANCE
    assert route.min_clearance_m >= CLEARANCE


def test_no_route_in_the_first_corridor_is_final():
    records = national_fences()
    # the goal inside a courtyard: a ring fence around it, no gap
    yard = shapely.Point(GOAL_XY).buffer(300.0).difference(shapely.Point(GOAL_XY).buffer(200.0))
    records.append(FenceRecord("prison/yard", "keep_out", COUNTRY.geom_to_wgs84(yard)))
    start, goal = lonlat(COUNTRY, *START_XY), lonlat(COUNTRY, *GOAL_XY)
    planner = CorridorPlanner(records, start, goal, clearance=CLEARANCE)
    with pytest.raises(NoRoute, match="the goal is enclosed by keep-out fence prison/yard"):
        planner.route()
    assert len(planner.corridors) == 1


def lines_until(proc, pattern, deadline):
    """Lines of ``proc``'s stdout until one matches ``pattern``, or the deadline passes (read
    straight from the pipe: no buffer holds a line back from the wait)."""
    fd = proc.stdout.fileno()
    sel = selectors.DefaultSelector()
    sel.register(fd, selectors.EVENT_READ)
    text = ""
    while time.monotonic() < deadline:
        if not sel.select(timeout=max(0.0, deadline - time.monotonic())):
            break
        chunk = os.read(fd, 65536).decode()
        if not chunk:
            break
        text += chunk
        lines = text.splitlines()
        if any(re.search(pattern, line) for line in lines[: None if text.endswith("\n") else -1]):
            return lines
    pytest.fail(f"no line matching {pattern!r} before the deadline: {text}")


def test_ctrl_c_stops_the_planner_at_once_and_writes_nothing(tmp_path):
    # a wall 40 km long across the way, in a field of 1,600 small fences: corridor after
    # corridor, each larger, until the last holds them all (many seconds of work)
    frame = LocalFrame(10.0, 50.0)
    records, _ = wall_of_pieces(frame, 20e3)
    ticks = np.arange(-20, 20) * 1000.0 + 500.0
    for x in ticks:
        for y in ticks:
            g = frame.geom_to_wgs84(shapely.Point(x, y).buffer(30.0, quad_segs=4))
            records.append(FenceRecord(f"mast/{x:.0f}/{y:.0f}", "keep_out", g))
    fences = write_fences(tmp_path / "field.geojson", records)
    start, goal = lonlat(frame, -1000.0, 1.0), lonlat(frame, 1000.0, -1.0)
    out = tmp_path / "out"
    out.mkdir()
    cmd = [sys.executable, "-m", "alphafence", "route", str(fences)]
    cmd += ["--from", cli_position(start), "--to", cli_position(goal)]
    cmd += ["-o", str(out / "m.plan"), "--waypoints", str(out / "m.waypoints")]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        # the second corridor: the planner is widening it, with the larger ones still to come
        lines_until(proc, r"^corridor 2: ", time.monotonic() + 120)
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=5)
        err = proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 130, err
    assert err.strip().splitlines()[-1] == "alphafence: interrupted"
    assert list(out.iterdir()) == []  # no mission, no waypoint file, no temporary file
