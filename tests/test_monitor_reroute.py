"""In-flight re-routing (``--imminent-action reroute``) without a vehicle: the engine's
decisions, the planner's goal and waypoints, and the runner flying a plan on a stub vehicle.

Scene (metres east/north of FRAME's origin): a keep-out square 100 m x 100 m, 200-300 m north,
the vehicle flying north at 10 m/s along x = 0, straight at it."""

import asyncio
import json
import math
import time
from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import Braking, stopping_distance
from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.reroute import (
    Rerouter,
    leg_timeout_s,
    mission_goal,
    parse_position_target,
    planning_lead_m,
    waypoints,
)
from alphafence.monitor.runner import Monitor
from alphafence.route.roadmap import NoRoute

FRAME = LocalFrame(-0.55, 51.43)
SQUARE = shapely.box(-50, 200, 50, 300)
CLEARANCE = 20.0
ALT_AMSL = 70.0


def record(site, kind, geom):
    return FenceRecord(site, kind, FRAME.geom_to_wgs84(geom))


@pytest.fixture
def records():
    return [
        record("prison/way/1", "keep_out", SQUARE),
        record("prison/way/1", "warning", SQUARE.buffer(30, join_style="mitre")),
    ]


@pytest.fixture
def fences(records):
    return FenceSet(records)


@pytest.fixture(scope="module")
def rerouter():
    return Rerouter([record("prison/way/1", "keep_out", SQUARE)], CLEARANCE)


def reroute_options(**kw):
    return MonitorOptions(
        enforce=True, imminent_action="reroute", reroute_clearance_m=CLEARANCE, **kw
    )


def at(t, x, y, vx=0.0, vy=0.0, mode="GUIDED"):
    lon, lat = FRAME.to_wgs84(x, y)
    return Sample(
        t, float(lat), float(lon), 20.0, vn=vy, ve=vx, mode=mode, armed=True, alt_amsl_m=ALT_AMSL
    )


def fly(t0, a, b, speed=10.0, dt=0.1, mode="GUIDED"):
    """Samples from a to b (metres) at ``speed``, starting at time t0 (b itself left out)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = float(np.hypot(*(b - a)))
    u = (b - a) / d
    for k in range(int(d / (speed * dt))):
        p = a + u * speed * dt * k
        yield at(t0 + k * dt, *p, *(u * speed), mode=mode)


def xy_of(event):
    x, y = FRAME.to_local(event["lon"], event["lat"])
    return float(x), float(y)


def actions(events):
    return [e["action"] for e in events if e["event"] == "action"]


# -- the engine ---------------------------------------------------------------------------
def test_reroute_is_emitted_once_at_imminent_early_enough_to_keep_the_clearance(fences):
    eng = Engine(fences, reroute_options())
    events = []
    for s in fly(0.0, (0, 0), (0, 199)):
        events += eng.step(s)
    imminent = [e for e in events if e["event"] == "level" and e["level"] == "IMMINENT"]
    reroutes = [e for e in events if e["event"] == "action" and e["action"] == "reroute"]
    assert len(imminent) == 1 and len(reroutes) == 1, events
    assert reroutes[0]["time"] == imminent[0]["time"]
    assert "re-route clearance" in imminent[0]["reason"]
    # IMMINENT comes while the vehicle can still stop the clearance short of the fence (to
    # within one sample: 1 m at 10 m/s and 10 Hz), and not earlier
    stop = stopping_distance(10.0, Braking())
    assert stop + CLEARANCE - 1.01 <= 200 - xy_of(imminent[0])[1] <= stop + CLEARANCE
    assert eng.rerouting
    # the same flight with the brake: IMMINENT only at the stopping distance
    brake = Engine(fences, MonitorOptions(enforce=True))
    late = [e for s in fly(0.0, (0, 0), (0, 199)) for e in brake.step(s) if e["event"] == "level"]
    late = [e for e in late if e["level"] == "IMMINENT"][0]
    assert xy_of(late)[1] > xy_of(imminent[0])[1] + CLEARANCE - 1.5


def test_no_second_action_while_rerouting_but_breach_still_acts(fences):
    eng = Engine(fences, reroute_options())
    events = []
    for s in fly(0.0, (0, 0), (0, 199)):
        events += eng.step(s)
        if actions(events):
            break
    t = events[-1]["time"]
    assert actions(events) == ["reroute"]
    assert eng.reroute_started(t + 0.05)[0]["event"] == "reroute"
    # turned away (the level relaxes), then heading at the fence again: IMMINENT, no action
    later = []
    for s in fly(t + 0.1, xy_of(events[-1]), (0, 0)):
        later += eng.step(s)
    t = later[-1]["time"] if later else t + 10
    for s in fly(t + 0.1, (0, 0), (0, 185)):
        later += eng.step(s)
    levels = [e["level"] for e in later if e["event"] == "level"]
    assert "IMMINENT" in levels and levels[0] != "IMMINENT", levels
    assert actions(later) == [], later
    # BREACH still takes the breach action, and ends the re-route
    for sample in fly(s.t + 0.1, (0, 185), (0, 230)):
        later += eng.step(sample)
    assert actions(later) == ["rtl"], later
    kinds = [e["event"] for e in later]
    assert kinds.index("reroute_cancelled") == kinds.index("action") - 1
    assert not eng.rerouting


def test_after_reroute_done_the_next_imminent_reroutes_again(fences):
    eng = Engine(fences, reroute_options())
    events = [e for s in fly(0.0, (0, 0), (0, 150)) for e in eng.step(s)]
    assert actions(events) == ["reroute"]
    eng.reroute_started(15.0)
    done = eng.reroute_done(15.1)
    assert done[0]["event"] == "reroute_done" and not eng.rerouting
    again = [e for s in fly(15.2, (0, 150), (0, 0)) for e in eng.step(s)]
    again += [e for s in fly(40.0, (0, 0), (0, 150)) for e in eng.step(s)]
    assert actions(again) == ["reroute"], again


def test_pilot_mode_change_cancels_the_reroute_and_backs_off(fences):
    eng = Engine(fences, reroute_options(backoff_s=30))
    events = [e for s in fly(0.0, (0, 0), (0, 150)) for e in eng.step(s)]
    t = events[-1]["time"]
    eng.reroute_started(t + 0.05)  # in GUIDED already: no mode change expected
    s = at(t + 0.2, *xy_of(events[-1]), mode="LOITER")  # the pilot switches to LOITER
    out = eng.step(s)
    assert [e["event"] for e in out][:2] == ["pilot_mode_change", "reroute_cancelled"], out
    assert not eng.rerouting and eng.backoff_until > s.t
    # and the fallback brake is withheld during the back-off
    failed = eng.reroute_failed(s.t + 1, "whatever")
    assert [e["event"] for e in failed] == ["reroute_failed", "action_withheld"]


def test_the_monitors_own_mode_changes_are_not_the_pilot(fences):
    """AUTO -> GUIDED (the first goto) and GUIDED -> AUTO (the resume) are the monitor's."""
    eng = Engine(fences, reroute_options())
    events = [e for s in fly(0.0, (0, 0), (0, 150), mode="AUTO") for e in eng.step(s)]
    t = events[-1]["time"]
    assert actions(events) == ["reroute"]
    eng.reroute_started(t, mode_change=True)
    out = eng.step(at(t + 0.3, -5, 150, mode="GUIDED"))
    out += eng.step(at(t + 5.0, -60, 170, mode="GUIDED"))
    eng.reroute_done(t + 9.0, resume=True)
    out += eng.step(at(t + 9.3, 0, 350, mode="AUTO"))
    assert not [e for e in out if e["event"] in ("pilot_mode_change", "reroute_cancelled")], out
    assert not eng.in_commanded_mode  # back in the pilot's mission: a LOITER now is theirs
    assert eng.backoff_until < 0


def test_reroute_failed_falls_back_to_brake(fences):
    eng = Engine(fences, reroute_options())
    for s in fly(0.0, (0, 0), (0, 150)):
        eng.step(s)
    assert eng.rerouting
    out = eng.reroute_failed(16.0, "the goal is inside keep-out fence prison/way/1")
    assert [e["event"] for e in out] == ["reroute_failed", "action"]
    assert out[0]["reason"] == "the goal is inside keep-out fence prison/way/1"
    assert out[1]["action"] == "brake" and out[1]["reason"] == "reroute_failed"
    assert not eng.rerouting and eng.expect_mode_change  # BRAKE is the monitor's mode


def test_reroute_is_only_an_imminent_action(tmp_path, capsys):
    with pytest.raises(InputError, match="breach_action: reroute"):
        MonitorOptions(breach_action="reroute")
    with pytest.raises(InputError, match="on_glitch: reroute"):
        MonitorOptions(on_glitch="reroute")
    with pytest.raises(InputError, match="reroute_clearance_m"):
        MonitorOptions(imminent_action="reroute", reroute_clearance_m=-1)
    feature = {
        "type": "Feature",
        "properties": {"site_id": "prison/1", "kind": "keep_out"},
        "geometry": shapely.geometry.mapping(FRAME.geom_to_wgs84(SQUARE)),
    }
    path = tmp_path / "fences.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    argv = ["monitor", "--connect", "udpin://127.0.0.1:1", "--fences", str(path)]
    code = main(argv + ["--allow-unsigned", "--enforce", "--breach-action", "reroute"])
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert code == 2 and len(errors) == 1 and "--breach-action reroute: re-routing" in errors[0]


# -- the planner --------------------------------------------------------------------------
def square_distance(lonlat_points):
    """Exact least distance of the legs through (lon, lat) points to SQUARE, in FRAME."""
    pts = np.asarray(lonlat_points, float)
    x, y = FRAME.to_local(pts[:, 0], pts[:, 1])
    return float(shapely.distance(shapely.LineString(np.column_stack([x, y])), SQUARE))


def test_goal_beyond_the_fence_along_the_track(rerouter):
    lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, 100.0))
    goal = rerouter.goal_beyond(lon, lat, 0.0, 10.0)  # heading north
    gx, gy = (float(v) for v in FRAME.to_local(*goal))
    assert abs(gx) < 0.5  # on the track
    d = float(shapely.distance(shapely.Point(gx, gy), SQUARE))
    assert CLEARANCE <= d <= CLEARANCE + 2.0 and gy > 300, (gx, gy, d)
    # heading north-east, the track leaves the square through its east side
    goal = rerouter.goal_beyond(lon, lat, 5.0, 10.0)
    gx, gy = (float(v) for v in FRAME.to_local(*goal))
    assert abs(gx - 0.5 * (gy - 100)) < 1.0
    assert CLEARANCE <= float(shapely.distance(shapely.Point(gx, gy), SQUARE)) <= CLEARANCE + 2
    # heading away from the fence, or not moving: no goal
    assert rerouter.goal_beyond(lon, lat, 0.0, -10.0) is None
    assert rerouter.goal_beyond(lon, lat, 0.0, 0.1) is None


def test_goal_beyond_skips_gaps_narrower_than_the_clearance():
    second = shapely.box(-50, 330, 50, 400)  # 30 m beyond the first: no clear point between
    r = Rerouter(
        [record("a", "keep_out", SQUARE), record("b", "keep_out", second)], clearance=CLEARANCE
    )
    lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, 100.0))
    x, y = (float(v) for v in FRAME.to_local(*r.goal_beyond(lon, lat, 0.0, 10.0)))
    assert y > 400 + CLEARANCE - 0.5 and abs(x) < 1, (x, y)


def test_route_keeps_the_clearance_and_goes_around(rerouter):
    lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, 120.0))
    goal = tuple(float(v) for v in FRAME.to_wgs84(0.0, 450.0))
    lead = planning_lead_m(10.0, Braking())
    plan = rerouter.plan(lon, lat, 0.0, 10.0, goal, lead)
    assert plan.waypoints[-1] == (round(goal[1], 7), round(goal[0], 7))
    assert all(w == (round(w[0], 7), round(w[1], 7)) for w in plan.waypoints)
    flown = [(lon, lat)] + [(w[1], w[0]) for w in plan.waypoints]
    assert square_distance(flown) >= CLEARANCE - 0.01, square_distance(flown)
    assert plan.clearance_m >= CLEARANCE and abs(plan.clearance_m - square_distance(flown)) < 0.1
    xs = [float(FRAME.to_local(w[1], w[0])[0]) for w in plan.waypoints]
    assert max(abs(x) for x in xs) >= 50 + CLEARANCE - 0.5  # around a side of the square
    # the planned route begins where the vehicle can stop, ahead on its track
    sx, sy = (float(v) for v in FRAME.to_local(*plan.start))
    assert abs(sx) < 0.5 and 120 + lead - 2.5 <= sy <= 120 + lead + 0.5, (sx, sy, lead)
    assert plan.length_m > 330


def test_route_from_inside_the_clearance_or_to_a_goal_in_the_fence_is_no_route(rerouter):
    lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, 120.0))
    inside = tuple(float(v) for v in FRAME.to_wgs84(0.0, 250.0))
    with pytest.raises(NoRoute, match="goal is inside keep-out fence"):
        rerouter.plan(lon, lat, 0.0, 10.0, inside, 10.0)
    near = tuple(float(v) for v in FRAME.to_wgs84(0.0, 190.0))
    goal = tuple(float(v) for v in FRAME.to_wgs84(0.0, 450.0))
    with pytest.raises(NoRoute, match="start is .* closer than the clearance"):
        rerouter.plan(*near, 0.0, 2.0, goal, 1.0)


def test_route_must_not_leave_a_keep_in():
    keep_in = shapely.box(-60, -100, 60, 500)  # too narrow to pass the square with 20 m
    r = Rerouter([record("sq", "keep_out", SQUARE), record("field", "keep_in", keep_in)], CLEARANCE)
    lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, 120.0))
    goal = tuple(float(v) for v in FRAME.to_wgs84(0.0, 450.0))
    with pytest.raises(NoRoute, match="leaves keep-in fence field"):
        r.plan(lon, lat, 0.0, 10.0, goal, 0.0)


def test_pure_helpers():
    lonlat = np.array([[-0.5, 51.4], [-0.500000123456, 51.400000987654], [-0.49, 51.41]])
    assert waypoints(lonlat) == [(51.400001, -0.5000001), (51.41, -0.49)]
    assert waypoints(lonlat, skip_start=False)[0] == (51.4, -0.5)
    assert leg_timeout_s(100) == pytest.approx(70.0) and leg_timeout_s(0) == 20.0
    target = {"lat_int": 514300000, "lon_int": -5500000, "type_mask": 0, "alt": 20}
    assert parse_position_target(json.dumps(target)) == (-0.55, 51.43)
    assert parse_position_target(json.dumps({**target, "type_mask": 3})) is None
    assert parse_position_target(json.dumps({**target, "lat_int": 0, "lon_int": 0})) is None
    assert parse_position_target("not json") is None

    def item(seq, command, x, y, frame=3):
        return SimpleNamespace(seq=seq, command=command, frame=frame, x=x, y=y, z=20.0)

    mission = [
        item(0, 16, 514300000, -5500000, frame=0),
        item(1, 22, 0, 0),
        item(2, 16, 514310000, -5510000),
        item(3, 20, 0, 0),
    ]
    assert mission_goal(mission, 2) == pytest.approx((-0.551, 51.431))
    assert mission_goal(mission, 1) is None  # takeoff where it is
    assert mission_goal(mission, 3) is None  # RTL
    assert mission_goal(mission, 9) is None


# -- the runner, on a stub vehicle ---------------------------------------------------------
class StubAction:
    """Records commands; a goto teleports the vehicle there (arrival at once)."""

    def __init__(self):
        self.calls = []
        self.monitor = None

    async def goto_location(self, lat, lon, alt, yaw):
        self.calls.append(("goto", lat, lon, alt, yaw))
        await asyncio.sleep(0)
        p = SimpleNamespace(latitude_deg=lat, longitude_deg=lon)
        self.monitor.latest["position"] = (time.monotonic(), p)

    async def hold(self):
        self.calls.append(("hold",))


async def run_reroute(fences, records, goal_xy):
    """Fly north at the square until the engine asks for a re-route, with the GUIDED target
    at goal_xy; returns (monitor, stub action) once the re-route task has finished."""
    action = StubAction()
    vehicle = SimpleNamespace(action=action, system=None)
    monitor = Monitor(vehicle, fences, reroute_options(), EventLog())
    action.monitor = monitor

    async def no_alert(text, event):
        return None

    monitor.commands.alert = no_alert
    monitor.reroute.rerouter = await Rerouter.build(records, CLEARANCE)
    glon, glat = (float(v) for v in FRAME.to_wgs84(*goal_xy))
    monitor.reroute.target = (time.monotonic(), glon, glat)
    for s in fly(0.0, (0, 0), (0, 199)):
        events = monitor.engine.step(s)
        for e in events:
            monitor.handle(e)
        if monitor.reroute.task is not None:
            break
    await asyncio.wait_for(monitor.reroute.task, 10)
    await asyncio.wait_for(settled(monitor), 30)  # the fallback action's own task, if any
    return monitor, action


async def settled(monitor):
    """Until every task the monitor spawned (actions, alerts) has ended, and those they
    spawned."""
    while monitor.pending:
        await asyncio.wait(set(monitor.pending))


async def test_runner_flies_the_route_to_the_guided_target(fences, records):
    monitor, action = await run_reroute(fences, records, (0.0, 450.0))
    kinds = [e["event"] for e in monitor.log.events]
    assert "reroute" in kinds and kinds[-1] == "reroute_done", kinds
    reroute = next(e for e in monitor.log.events if e["event"] == "reroute")
    assert reroute["goal_source"] == "guided target"
    gotos = [c for c in action.calls if c[0] == "goto"]
    assert [tuple(w) for w in reroute["waypoints"]] == [(c[1], c[2]) for c in gotos]
    assert all(c[3] == ALT_AMSL and math.isnan(c[4]) for c in gotos)
    assert ("hold",) not in action.calls and not monitor.engine.rerouting
    assert reroute["clearance_m"] >= CLEARANCE
    start = (reroute["lon"], reroute["lat"])
    assert square_distance([start] + [(c[2], c[1]) for c in gotos]) >= CLEARANCE - 0.01


async def test_runner_falls_back_to_brake_when_there_is_no_route(fences, records):
    monitor, action = await run_reroute(fences, records, (0.0, 250.0))  # target in the square
    events = monitor.log.events
    failed = [e for e in events if e["event"] == "reroute_failed"]
    assert len(failed) == 1 and "goal is inside keep-out fence prison/way/1" in failed[0]["reason"]
    assert "\n" not in failed[0]["reason"]
    assert [e["action"] for e in events if e["event"] == "action"] == ["reroute", "brake"]
    assert action.calls == [("hold",)]  # no goto at all, then MAVSDK's hold (ArduPilot BRAKE)
    assert [e for e in events if e["event"] == "action_done" and e["action"] == "brake"]
