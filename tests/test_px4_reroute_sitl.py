"""The monitor flies a PX4 vehicle round a keep-out zone (``--imminent-action reroute``; PX4
SITL, SIH quadrotor, real time), on each vehicle link.

The zone is test_px4_flight_sitl.py's 100 m x 200 m rectangle, its near edge ZONE_EDGE east of
home; it is the monitor's only fence (no warning layer: the planner would route round that too,
and the clearance would not be tested) and PX4's own fence action is off. The monitor runs with
``enforce`` and ``imminent_action="reroute"`` (20 m clearance) as ``Monitor(...).run(stop)`` on
the test's own connection.

* Goto: take off to 20 m, a goto (PX4's reposition, in Hold) 600 m east, through the zone. The
  goal is the vehicle's own reposition target (POSITION_TARGET_GLOBAL_INT); the waypoints are
  flown as repositions, in Hold throughout, and it ends hovering at the goal.
* Mission: takeoff, a waypoint 450 m east (the leg to it crosses the zone), one 500 m east,
  land. The goal is the item it flies to (1); the re-route switches to Hold, and after the goal
  the mission resumes at item 2 in Mission mode; none of those mode changes is the pilot's.

Asserted: one ``reroute`` (goal and its source), a ``reroute_done``, no failure, cancel, pilot
mode change or BREACH; from the goto (the mission's start) on, every reported position keeps
``CLEARANCE - TOLERANCE`` from the zone; the goal reached (goto: stopped there).

Measured (2026-12-06, 10 m/s, both links): see the print and docs/px4.md.
"""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.coords import to_e7
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink import ids
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import apply_params
from alphafence.vehicle.values import RawItem
from tests.sitl_flight import upload_mission
from tests.test_px4_flight_sitl import (
    ALTITUDE,
    HOME,
    SPEED,
    STOPPED_MPS,
    TARGET_EAST,
    Track,
    _take_off,
    _watched,
    zone_local,
)

pytestmark = [pytest.mark.sitl, pytest.mark.px4, pytest.mark.alone]  # PX4 in real time
CLEARANCE = 20.0
TOLERANCE = 1.5
MISSION_GOAL_EAST = 450.0
MISSION_NEXT_EAST = 500.0
AT_GOAL_M = 5.0


def _mission(frame):
    """PX4's mission (no home item): takeoff here, a waypoint beyond the zone, one further
    on, land there."""

    def item(seq, command, east, z=ALTITUDE):
        lon, lat = frame.to_wgs84(np.array([east]), np.array([0.0]))
        return RawItem(seq, ids.MAV_FRAME_GLOBAL_RELATIVE_ALT, command, int(seq == 0), 1,
                       0.0, 0.0, 0.0, float("nan"), to_e7(float(lat[0])), to_e7(float(lon[0])),
                       float(z), ids.MAV_MISSION_TYPE_MISSION)  # fmt: skip

    return [
        item(0, ids.MAV_CMD_NAV_TAKEOFF, 0.0),
        item(1, ids.MAV_CMD_NAV_WAYPOINT, MISSION_GOAL_EAST),
        item(2, ids.MAV_CMD_NAV_WAYPOINT, MISSION_NEXT_EAST),
        item(3, ids.MAV_CMD_NAV_LAND, MISSION_NEXT_EAST, 0.0),
    ]


def _kinds(log, *kinds):
    return [e for e in log.events if e["event"] in kinds]


async def _modes(vehicle, seen):
    async for m in vehicle.telemetry.subscribe_flight_mode():
        if not seen or seen[-1][1] != m.name:
            seen.append((asyncio.get_running_loop().time(), m.name))


async def _fly(vehicle, track, log, mission, marks):
    frame = track.frame
    if mission:
        await upload_mission(vehicle, _mission(frame))
        await vehicle.action.arm()
        marks["start"] = len(track.east)
        await vehicle.mission_raw.start_mission()
    else:
        amsl = await _take_off(vehicle, ALTITUDE)
        lon, lat = frame.to_wgs84(np.array([TARGET_EAST]), np.array([0.0]))
        await vehicle.action.goto_location(float(lat[0]), float(lon[0]), amsl, float("nan"))
        marks["start"] = len(track.east)
    ended = ("reroute_done", "reroute_failed", "reroute_cancelled")
    await track.until("the re-route's end", lambda: _kinds(log, *ended), 120)
    assert not _kinds(log, "reroute_failed", "reroute_cancelled"), log.events
    goal = (MISSION_NEXT_EAST if mission else TARGET_EAST, 0.0)

    def at_goal():
        return math.hypot(track.east[-1] - goal[0], track.north[-1] - goal[1]) < AT_GOAL_M

    await track.until("the goal", at_goal, 90)
    await track.until("stopped", lambda: track.speed[-1] < STOPPED_MPS, 30)


@pytest.mark.parametrize("mission", [False, True], ids=["goto", "mission"])
async def test_the_monitor_flies_a_px4_vehicle_round_the_zone(px4, link, mission):
    frame = LocalFrame(*HOME)
    zone = zone_local()
    fences = FenceSet([FenceRecord("test/zone", "keep_out", frame.geom_to_wgs84(zone))])
    track = Track(frame)
    log = EventLog()
    marks, modes = {}, []
    options = MonitorOptions(enforce=True, imminent_action="reroute", reroute_clearance_m=CLEARANCE)
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        await apply_params(vehicle, {"GF_ACTION": 0, "MPC_XY_CRUISE": SPEED})
        stop = asyncio.Event()
        monitor = Monitor(vehicle, fences, options, log)
        task = asyncio.create_task(monitor.run(stop))
        watcher = asyncio.ensure_future(_modes(vehicle, modes))
        try:
            for _ in range(600):  # the planner is built in a worker thread as the monitor starts
                if _kinds(log, "reroute_ready", "reroute_unavailable"):
                    break
                await asyncio.sleep(0.05)
            assert _kinds(log, "reroute_ready"), log.events
            await _watched(vehicle, track, lambda: _fly(vehicle, track, log, mission, marks), px4)
        finally:
            stop.set()
            watcher.cancel()
            await asyncio.wait_for(asyncio.gather(task, watcher, return_exceptions=True), 10)
    events = list(log.events)
    t0 = events[0]["time"] if events else 0.0
    brief = ", ".join(
        f"{e['event']} {e.get('level') or e.get('action') or e.get('goal_source') or ''}"
        f"@{e['time'] - t0:.2f} {e.get('mode') or ''}"
        for e in events
    )
    reroutes, dones = _kinds(log, "reroute"), _kinds(log, "reroute_done")
    assert len(reroutes) == 1 and len(dones) == 1, brief
    reroute, done = reroutes[0], dones[0]
    bad = ("reroute_failed", "reroute_cancelled", "action_failed", "pilot_mode_change")
    assert not _kinds(log, *bad), brief
    assert [e["action"] for e in events if e["event"] == "action"] == ["reroute"], brief
    assert not [e for e in events if e["event"] == "level" and e["level"] == "BREACH"], brief
    gx, gy = (float(v) for v in frame.to_local(reroute["goal"][1], reroute["goal"][0]))
    # the mode at the re-route and every one after it
    after = [
        m
        for k, (t, m) in enumerate(modes)
        if modes[k + 1 :] == [] or modes[k + 1][0] > reroute["time"]
    ]
    xy = np.column_stack([track.east, track.north])[marks["start"] :]
    distances = shapely.distance(shapely.points(xy), zone)
    worst = int(np.argmin(distances))
    turned = max(x for x, y in xy if abs(y) < 100.0 and x < float(zone.bounds[0]))
    print(
        f"\nPX4 re-route ({link}, {'mission' if mission else 'goto'}): "
        f"{len(reroute['waypoints'])} waypoints, {reroute['length_m']:.0f} m, planned clearance "
        f"{reroute['clearance_m']:.2f} m; turned {zone.bounds[0] - turned:.1f} m short of the "
        f"zone; least distance {distances[worst]:.2f} m at ({xy[worst, 0]:.0f}, "
        f"{xy[worst, 1]:.0f}); modes {[m for _, m in modes]}"
    )
    if mission:
        assert reroute["goal_source"] == "mission item 1", reroute
        assert done["resume_at"] == 2, done
        assert math.hypot(gx - MISSION_GOAL_EAST, gy) < 0.5, (gx, gy)
        assert after == ["MISSION", "HOLD", "MISSION"], modes
    else:
        assert reroute["goal_source"] == "reposition target", reroute
        assert math.hypot(gx - TARGET_EAST, gy) < 0.5, (gx, gy)
        assert after == ["HOLD"], modes  # a reposition flies in Hold: no mode change
    assert reroute["clearance_m"] >= CLEARANCE, reroute
    assert distances[worst] >= CLEARANCE - TOLERANCE, distances[worst]
