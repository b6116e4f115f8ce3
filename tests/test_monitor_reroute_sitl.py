"""The monitor re-routes a copter around a keep-out square in flight (real copter SITL).

The setup is test_monitor_flight_sitl.py's: an exclusion square (100 m x 100 m, near edge 150 m
north of home) uploaded to ArduPilot with the ``copter-rtl`` parameters (so that ArduPilot's
own fence would report a breach, and RTL, if the copter entered it), and a flight north at
10 m/s straight through the square towards a point 400 m north. The monitor gets the same
square as its only keep-out fence (no warning layer: the planner would otherwise route around
that too, and the clearance would not be tested) and runs with ``enforce`` and
``imminent_action="reroute"`` (20 m clearance) as ``Monitor(...).run(stop)`` on the test's own
connection (only one program can own the SITL UDP port). FENCE_STATUS is read with the
Vehicle's ``messages``.

* GUIDED (the issue's case): GUIDED takeoff to 20 m, goto 400 m north. At IMMINENT the goal is
  the vehicle's own GUIDED target (POSITION_TARGET_GLOBAL_INT); the waypoints are flown with goto
  (DO_REPOSITION) in GUIDED and the copter ends hovering at the goal.
* AUTO: a mission (takeoff, a waypoint 400 m north, one 450 m north, land) flown with
  ``start_mission``. The goal is the mission item it flies to (item 2); goto switches to GUIDED,
  and after the goal the mission resumes at item 3 in AUTO; none of those mode changes may be
  taken for the pilot's.

Asserted: exactly one ``reroute`` (goal from the GUIDED target / mission item 2, planned
clearance >= 20 m) and a ``reroute_done`` in the monitor's log, no fallback, cancel, failure,
pilot mode change or BREACH; ArduPilot never reports a breach (every FENCE_STATUS has
breach_status 0, no RTL, no "fence breached"); every reported position from the goto (AUTO: the
mission start) on is at least ``CLEARANCE - TOLERANCE`` from the square; the copter gets within
5 m of the goal (GUIDED: ends there, stopped, at 20 m).

Measured (egham, speedup 5, 2-core machine; 10 GUIDED and 6 AUTO runs, 4 of them side by side
with another SITL test): IMMINENT ("cannot stop 20 m (the re-route clearance) before the fence
ahead") 55.5-56.7 m before the edge at 9.9-10.0 m/s (37 m stopping distance + 20 m, to within
one position sample); the roadmap of one fence built in 0.004-0.007 s, the route planned in
0.005-0.014 s wall; 6 waypoints, 360-361 m, planned clearance 20.05 m, past the square's east
side (in AUTO, in 3 of 6 runs, the mirror-image west side: a tie broken by centimetres). The
planned route begins 35 m on along the track, where the monitor's braking model says the
copter stops; it turned at y = 129.2-129.7 m, within about a metre of that: 20.3-20.8 m short
of the edge. The least distance of any reported position to the square 20.08-20.11 m, on the
side leg at x = +-70 m (GUIDED tracks the straight legs to within 0.1 m of the planned
20.05 m); ``reroute_done`` 10.6-10.7 s wall (about 53 s of flight) after the re-route; GUIDED
ends 0.04 m from the goal (AUTO passes within 0.03 m of it, then resumes at item 3);
FENCE_STATUS breach_status 0 throughout; no mode change taken for the pilot's. TOLERANCE
(1.5 m): the side legs keep 20.08 m, but the turn is only 0.3-0.8 m above the clearance and
moves with IMMINENT's detection (one position sample: 1 m at 10 m/s) and with the monitor's
wall-clock latency (times 5 in flight at speedup 5; it turned 0.2 m later side by side). Each
test takes about 27 s wall, SITL start included.
"""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.coords import to_e7
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_LAND as NAV_LAND,
)
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_TAKEOFF as NAV_TAKEOFF,
)
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_WAYPOINT as NAV_WAYPOINT,
)
from alphafence.mavlink.ids import MAV_FRAME_GLOBAL, MAV_FRAME_GLOBAL_RELATIVE_ALT
from alphafence.mavlink.ids import MAV_MISSION_TYPE_MISSION as MISSION_TYPE_MISSION
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from tests.sitl_flight import (
    ALTITUDE,
    ARM_TIMEOUT,
    HALF_WIDTH,
    NEAR_EDGE,
    FlightLog,
    exclusion_items,
    fence_and_telemetry,
    fence_reports,
    retry,
    speedup_options,
    square_local,
    take_off,
    until,
    unwatch,
    upload_mission,
    watch,
    within,
)

pytestmark = [pytest.mark.sitl, pytest.mark.alone]  # turns within 1.5 m of its clearance

EGHAM = {"home": "egham", "speedup": 5}

TARGET_NORTH = 400.0  # beyond the square: GUIDED ignores targets inside an exclusion zone
AUTO_NEXT_M = 50.0  # AUTO: the mission item after the one beyond the square, further north
NEXT_NORTH = TARGET_NORTH + AUTO_NEXT_M
SPEED = 10.0
CLEARANCE = 20.0
TOLERANCE = 1.5  # metres the flown track may come closer than the clearance (see above)
AT_GOAL_M = 5.0
STOPPED_MPS = 0.3

WALL_TIMEOUT = 150.0


def _events(log, kind):
    return [e for e in log.events if e["event"] == kind]


RELATIVE = MAV_FRAME_GLOBAL_RELATIVE_ALT


def _mission(frame: LocalFrame, home):
    """Raw mission items: home (seq 0), takeoff here, a waypoint beyond the square (the leg to
    it crosses the square), one 50 m further on, land there."""
    from alphafence.vehicle.values import RawItem

    def item(seq, command, x_east=None, y_north=None, z=ALTITUDE, frame_id=RELATIVE):
        lat = lon = 0
        if x_east is not None:
            lo, la = frame.to_wgs84(x_east, y_north)
            lat, lon = to_e7(float(la)), to_e7(float(lo))
        return RawItem(
            seq,
            frame_id,
            command,
            1 if seq == 1 else 0,
            1,
            0.0,
            0.0,
            0.0,
            0.0,
            lat,
            lon,
            float(z),
            MISSION_TYPE_MISSION,
        )

    return [
        item(0, NAV_WAYPOINT, 0.0, 0.0, home.alt, frame_id=MAV_FRAME_GLOBAL),
        item(1, NAV_TAKEOFF),
        item(2, NAV_WAYPOINT, 0.0, TARGET_NORTH),
        item(3, NAV_WAYPOINT, 0.0, TARGET_NORTH + AUTO_NEXT_M),
        item(4, NAV_LAND, z=0.0),
    ]


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_monitor_reroutes_around_the_keep_out_without_a_breach(sitl):
    """GUIDED: the goal is the vehicle's own GUIDED target; it ends there, hovering."""
    log = FlightLog(LocalFrame(sitl.home.lon, sitl.home.lat))
    results = {}
    await within(_fly(sitl, log, results, auto=False), WALL_TIMEOUT, log)
    _check(sitl, log, results, auto=False)


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_monitor_reroutes_an_auto_mission_and_resumes_it(sitl):
    """AUTO: the goal is the mission item the vehicle flies to; after it the mission resumes
    at the next item, in AUTO, and none of the monitor's mode changes is taken for the
    pilot's."""
    log = FlightLog(LocalFrame(sitl.home.lon, sitl.home.lat))
    results = {}
    await within(_fly(sitl, log, results, auto=True), WALL_TIMEOUT, log)
    _check(sitl, log, results, auto=True)


async def _fly(sitl, log: FlightLog, results, auto: bool):
    frame = log.frame
    async with open_vehicle(sitl.connection_url) as vehicle:
        log.texts = vehicle.texts
        watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence", "progress")
        monitor_log = EventLog()
        log.events = monitor_log.events
        stop = asyncio.Event()
        monitor_task = None
        try:
            await fence_and_telemetry(vehicle, log, exclusion_items(frame))

            fences = FenceSet(
                [FenceRecord("test/square", "keep_out", frame.geom_to_wgs84(square_local()))]
            )
            options = speedup_options(
                sitl.speedup, enforce=True, imminent_action="reroute", reroute_clearance_m=CLEARANCE
            )
            monitor = Monitor(vehicle, fences, options, monitor_log)
            monitor_task = asyncio.create_task(monitor.run(stop))
            await until("the route planner", lambda: _events(log, "reroute_ready"), 10, log)

            action = vehicle.action
            if auto:  # the mission's own NAV_TAKEOFF takes off, then it flies north
                await upload_mission(vehicle, _mission(frame, sitl.home))
                await retry("arming", action.arm, ARM_TIMEOUT)
                results["t_goto"] = time.monotonic()
                await vehicle.mission_raw.start_mission()
                await until("AUTO", lambda: log.mode() == "AUTO", 5, log)
            else:
                await take_off(action, log)
                lon, lat = frame.to_wgs84(0.0, TARGET_NORTH)
                await action.set_current_speed(SPEED)
                await action.goto_location(float(lat), float(lon), sitl.home.alt + ALTITUDE, 0.0)
                results["t_goto"] = time.monotonic()
            await until(
                "the monitor's re-route",
                lambda: _events(log, "reroute") or _events(log, "reroute_failed"),
                60,
                log,
                poll=0.01,
            )
            assert not _events(log, "reroute_failed"), log.summary()
            await until(
                "reroute_done",
                lambda: _events(log, "reroute_done") or _events(log, "reroute_failed"),
                90,
                log,
            )
            results["t_done"] = time.monotonic()
            if auto:
                await until("AUTO again", lambda: log.mode() == "AUTO", 10, log)
                await until(
                    "the next mission item",
                    lambda: (
                        math.hypot(log.positions[-1][1], log.positions[-1][2] - NEXT_NORTH)
                        < AT_GOAL_M
                    ),
                    60,
                    log,
                )
                await until("landing", lambda: log.progress[-1][1] >= 4, 30, log)
            else:
                await until(
                    "stopped at the goal", lambda: log.speed() < STOPPED_MPS, 30, log, poll=0.02
                )
                # 10 s of the vehicle's time: still there, still no breach
                await fence_reports(log, 10.0, "FENCE_STATUS at the goal")
            results["t_end"] = time.monotonic()
            assert not monitor_task.done(), "the monitor stopped by itself"
            results["checks"] = monitor.engine.checks
        finally:
            stop.set()
            if monitor_task is not None:
                await asyncio.wait_for(asyncio.gather(monitor_task, return_exceptions=True), 5)
            await unwatch(watchers)


def _check(sitl, log: FlightLog, results, auto: bool):
    frame = log.frame
    square = square_local()
    events = list(log.events)
    brief = ", ".join(
        f"{e['event']} {e.get('level') or e.get('action') or ''}@{e['time']:.2f}" for e in events
    )
    (ready,) = [e for e in events if e["event"] == "reroute_ready"]
    reroutes = [e for e in events if e["event"] == "reroute"]
    assert len(reroutes) == 1, brief
    reroute = reroutes[0]
    assert [e for e in events if e["event"] == "reroute_done"], brief
    assert [e["action"] for e in events if e["event"] == "action"] == ["reroute"], brief
    bad = ("reroute_failed", "reroute_cancelled", "action_failed", "pilot_mode_change")
    assert not [e for e in events if e["event"] in bad], brief
    assert not [e for e in events if e["event"] == "level" and e["level"] == "BREACH"], brief
    if auto:
        assert reroute["goal_source"] == "mission item 2", reroute
        (done,) = [e for e in events if e["event"] == "reroute_done"]
        assert done["resume_at"] == 3, done
        after = [m for t, m in log.modes if t >= reroute["time"]]
        assert after == ["GUIDED", "AUTO"], after
    else:
        assert reroute["goal_source"] == "guided target", reroute
    assert reroute["clearance_m"] >= CLEARANCE, reroute
    gx, gy = (float(v) for v in frame.to_local(reroute["goal"][1], reroute["goal"][0]))
    assert abs(gx) < 0.5 and abs(gy - TARGET_NORTH) < 0.5, (gx, gy)

    # ArduPilot: no breach from takeoff to the end, no RTL, FENCE_STATUS kept coming
    assert log.first_breach() is None, [f for _, f in log.fence if f["breach_status"]]
    assert log.fence[-1][0] > results["t_end"] - 2.0, "FENCE_STATUS stopped arriving"
    assert "RTL" not in [m for _, m in log.modes], log.summary()
    assert not [t for t, s in log.texts if "fence breached" in s.lower()], log.summary()

    flown = [p for p in log.positions if p[0] >= results["t_goto"]]
    xy = np.array([p[1:3] for p in flown])
    distances = shapely.distance(shapely.points(xy), square)
    worst = int(np.argmin(distances))
    before = [s for t, s in log.speeds if results["t_goto"] <= t <= reroute["time"]]
    final = log.positions[-1]
    if auto:  # it flew through the goal (the mission item) and on to the next one
        done_t = next(e["time"] for e in events if e["event"] == "reroute_done")
        final = min(
            (p for p in log.positions if p[0] <= done_t + 0.5),
            key=lambda p: math.hypot(p[1] - gx, p[2] - gy),
        )
    to_goal = math.hypot(final[1] - gx, final[2] - gy)
    t_imminent = next(
        e["time"] for e in events if e["event"] == "level" and e["level"] == "IMMINENT"
    )
    y_imminent = float(frame.to_local(reroute["lon"], reroute["lat"])[1])
    wps = np.array([frame.to_local(lon, lat) for lat, lon in reroute["waypoints"]], float)
    planned = ", ".join(f"({x:.0f}, {y:.0f})" for x, y in wps)
    # how far the copter carried on towards the square before it turned
    turned = max(p[2] for p in flown if abs(p[1]) < HALF_WIDTH and p[2] < NEAR_EDGE)
    print(
        f"\nreroute: planner built in {ready['build_s']:.3f} s; IMMINENT at y={y_imminent:.1f} m "
        f"({NEAR_EDGE - y_imminent:.1f} m before the edge) at {max(before):.1f} m/s; planned in "
        f"{reroute['plan_s']:.3f} s wall ({reroute['time'] - t_imminent:.3f} s after IMMINENT): "
        f"{len(reroute['waypoints'])} waypoints, {reroute['length_m']:.0f} m, planned clearance "
        f"{reroute['clearance_m']:.2f} m [{planned}]; turned at y={turned:.1f} m "
        f"({NEAR_EDGE - turned:.1f} m short of the edge); flown min distance to the square "
        f"{distances[worst]:.2f} m at x={xy[worst, 0]:.1f} y={xy[worst, 1]:.1f}; reroute_done "
        f"{results['t_done'] - reroute['time']:.2f} s wall after the reroute; final "
        f"{to_goal:.2f} m from the goal at alt {final[3]:.1f} m; {len(log.fence)} FENCE_STATUS, "
        f"breach_status {sorted({f['breach_status'] for _, f in log.fence})}; modes "
        f"{[m for _, m in log.modes]}; {results['checks']} checks, speedup "
        f"{sitl.speedup:g} | monitor: {brief}"
    )
    assert max(before) > 0.8 * SPEED, f"only {max(before):.1f} m/s before the re-route"
    assert distances[worst] >= CLEARANCE - TOLERANCE, (
        f"{distances[worst]:.2f} m from the square at x={xy[worst, 0]:.1f} y={xy[worst, 1]:.1f}"
    )
    assert to_goal <= AT_GOAL_M, f"{to_goal:.1f} m from the goal | {log.summary()}"
    assert abs(final[3] - ALTITUDE) < 3.0, final
    if not auto:
        assert log.speed() < STOPPED_MPS, log.summary()
