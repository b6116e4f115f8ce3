"""The companion monitor in a real flight (copter SITL): it warns before ArduPilot's own fence
breach, and with ``enforce`` it stops the vehicle before the fence.

The setup is tests/sitl_flight.py's: an exclusion square (100 m x 100 m, near edge 150 m
north of home) uploaded to ArduPilot with the ``copter-rtl`` parameters, a GUIDED takeoff to
20 m and a goto 400 m north at 10 m/s, straight through the square. The monitor gets the same
square as a keep-out fence plus a 30 m warning layer around it, and runs as
``Monitor(vehicle, fences, options, log).run(stop)`` on the test's own connection (only one
program can own the SITL UDP port). FENCE_STATUS is read with the Vehicle's ``messages``. The
enforcing flight runs on each vehicle link (the ``link`` fixture: pymavlink and MAVSDK), the
alert-only one on the default link.

Times. The engine stamps each sample with its arrival time (``time.monotonic()``, wall
seconds), and so does this test for every FENCE_STATUS, mode and STATUSTEXT: all event times
are on the same clock and the same link, so their differences are honest wall-clock leads.
SITL runs faster than real time, so a lead in flight (vehicle) seconds is the wall lead times
the *effective* speedup, measured on the flight itself: the distance flown per wall second
divided by the ground speed the vehicle reports (its own m/s in its own time). As a cross-check
the lead is also given by distance: metres from the fence edge at the event / ground speed.
ArduPilot's breach time is the earliest of: the first FENCE_STATUS with breach_status 1, the
switch to RTL, the "fence breached" STATUSTEXT.

Measured (egham, speedup 5, effective 5.02-5.03; 4 runs of each test): WARNING ("breach
predicted in 15 s") 13.2-13.3 s of flight before ArduPilot's breach, about 131 m before the
edge; IMMINENT ("cannot stop before the fence ahead") 3.15-3.22 s of flight before it (31-32 m)
with the earlier 1.0 s reaction time (32 m stopping distance at 10 m/s); the default is now
1.5 s (37 m), which puts IMMINENT about 3.7 s ahead by construction.
With enforce, the brake is the link's hold(), which ArduCopter carries out as BRAKE (custom
mode 17; both links name it HOLD, as MAVSDK does): the copter stops 0.93-0.95 s wall (about
4.7 s of flight) after the IMMINENT, 10.2-10.8 m short of the edge (farthest 139.2-139.8 m
north) with the 1.0 s reaction time; with the 1.5 s default, IMMINENT at 36.4 m and the stop
15.7-15.8 m short (farthest 134.2-134.3 m), the same on the pymavlink and the MAVSDK link
(2026-11-30). ArduPilot reports no breach. Each test takes about 18-20 s wall, SITL start
included.
"""

from __future__ import annotations

import asyncio
import functools
import json
import statistics
import time

import pytest

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink import ids
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.observe import Observer
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from tests.sitl_flight import (
    ALTITUDE,
    HALF_WIDTH,
    NEAR_EDGE,
    FlightLog,
    exclusion_items,
    fence_and_telemetry,
    fence_reports,
    speedup_options,
    square_local,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

_until = functools.partial(until, poll=0.02)  # finer timing for the lead measurements
pytestmark = pytest.mark.sitl

EGHAM = {"home": "egham", "speedup": 5}

WARNING_BUFFER = 30.0  # the monitor's warning layer around the square
TARGET_NORTH = 400.0  # beyond the square: GUIDED ignores targets inside an exclusion zone
SPEED = 10.0

WALL_TIMEOUT = 120.0
MIN_LEAD_S = 3.0  # flight seconds before ArduPilot's own breach (the requirement)
STOPPED_MPS = 0.3
WATCH_AFTER_STOP = 30.0  # seconds of the vehicle's time (FENCE_STATUS) of no breach after stopping

COPTER_MODES = {  # ArduCopter's custom_mode
    ids.COPTER_MODE_GUIDED: "GUIDED",
    ids.COPTER_MODE_LOITER: "LOITER",
    ids.COPTER_MODE_RTL: "RTL",
    ids.COPTER_MODE_BRAKE: "BRAKE",
}


def _monitor_fences(frame: LocalFrame) -> FenceSet:
    square = square_local()
    return FenceSet(
        [
            FenceRecord("test/square", "keep_out", frame.geom_to_wgs84(square)),
            FenceRecord(
                "test/square-warning", "warning", frame.geom_to_wgs84(square.buffer(WARNING_BUFFER))
            ),
        ]
    )


def _brief(events) -> str:
    return ", ".join(
        f"{e['event']} {e.get('level') or e.get('action') or e.get('mode') or ''}@{e['time']:.2f}"
        for e in events
    )


def _level_event(events, level):
    return next((e for e in events if e["event"] == "level" and e["level"] == level), None)


def _y_at(event, frame):
    return float(frame.to_local(event["lon"], event["lat"])[1])


def _effective_speedup(log: FlightLog, t0: float, t1: float) -> float:
    """Metres flown per wall second / the vehicle's own ground speed, on the straight leg."""
    leg = [p for p in log.positions if t0 <= p[0] <= t1]
    fast = [s for t, s in log.speeds if t0 <= t <= t1]
    assert len(leg) >= 5 and fast, "too few samples on the straight leg"
    wall_speed = (leg[-1][2] - leg[0][2]) / (leg[-1][0] - leg[0][0])
    return wall_speed / statistics.mean(fast)


class _Trace(Observer):
    """Every telemetry sample the monitor stepped on, in order."""

    def __init__(self, samples: list):
        self.samples = samples

    def on_step(self, step):
        self.samples.append(step.sample)


class _Flight:
    """One flight with the monitor running on the test's own connection."""

    def __init__(self, sitl, enforce: bool):
        self.sitl = sitl
        self.frame = LocalFrame(sitl.home.lon, sitl.home.lat)
        self.log = FlightLog(self.frame)
        self.enforce = enforce
        self.monitor_log = None
        self.trace = []  # every telemetry sample the monitor saw, for the replay check
        self.t_goto = None

    async def run(self, body):
        log, frame = self.log, self.frame
        async with open_vehicle(self.sitl.connection_url) as vehicle:
            self.vehicle = vehicle
            log.texts = vehicle.texts
            watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence", "custom_modes")
            self.monitor_log = EventLog()
            log.events = self.monitor_log.events
            stop = asyncio.Event()
            monitor_task = None
            try:
                await fence_and_telemetry(vehicle, log, exclusion_items(frame), poll=0.02)

                monitor = Monitor(
                    vehicle,
                    _monitor_fences(frame),
                    speedup_options(self.sitl.speedup, enforce=self.enforce),
                    self.monitor_log,
                    observers=[_Trace(self.trace)],
                )
                monitor_task = asyncio.create_task(monitor.run(stop))

                action = vehicle.action
                await take_off(action, log, poll=0.02)
                assert not log.first_breach(), "breach before the vehicle was sent anywhere"
                assert not [e for e in log.events if e["event"] == "level"], log.summary()

                lon, lat = frame.to_wgs84(0.0, TARGET_NORTH)
                await action.set_current_speed(SPEED)
                await action.goto_location(
                    float(lat), float(lon), self.sitl.home.alt + ALTITUDE, 0.0
                )
                self.t_goto = time.monotonic()
                await body(self)
                assert monitor.engine.checks >= 50, monitor.engine.checks
                assert not monitor_task.done(), "the monitor stopped by itself"
            finally:
                stop.set()
                if monitor_task is not None:
                    await asyncio.wait_for(asyncio.gather(monitor_task, return_exceptions=True), 5)
                await unwatch(watchers)


def _ardupilot_breach_time(log: FlightLog, since: float):
    breach = log.first_breach()
    times = [breach[0] if breach else None]
    times.append(next((t for t, m in log.modes if m == "RTL" and t >= since), None))
    times.append(
        next((t for t, s in log.texts if t >= since and "fence breached" in s.lower()), None)
    )
    times = [t for t in times if t is not None]
    return min(times) if times else None


async def _fly(sitl, enforce, body):
    flight = _Flight(sitl, enforce)
    await within(flight.run(body), WALL_TIMEOUT, flight.log)
    return flight


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_monitor_warns_well_before_the_onboard_fence_breach(sitl):
    """(a) alert only: WARNING and IMMINENT at least 3 s of flight before ArduPilot breaches."""
    results = {}

    async def body(flight: _Flight):
        log = flight.log
        await _until(
            "ArduPilot's fence breach",
            lambda: _ardupilot_breach_time(log, flight.t_goto),
            60,
            log,
            poll=0.01,
        )
        # every report of it, and the monitor's own BREACH (the copter overshoots into the
        # square), before the earliest is taken
        since = flight.t_goto
        await _until("FENCE_STATUS breach", log.first_breach, 10, log)
        await _until("RTL", lambda: "RTL" in [m for _, m in log.modes], 10, log)
        await _until(
            "the breach STATUSTEXT",
            lambda: any(t >= since and "fence breached" in s.lower() for t, s in log.texts),
            10,
            log,
        )
        await _until("the monitor's BREACH", lambda: _level_event(log.events, "BREACH"), 10, log)
        results["t_breach"] = _ardupilot_breach_time(log, since)

    flight = await _fly(sitl, False, body)
    log, frame = flight.log, flight.frame
    events = list(log.events)
    t_breach = results["t_breach"]
    warning, imminent, breach = (
        _level_event(events, lv) for lv in ("WARNING", "IMMINENT", "BREACH")
    )
    assert warning and imminent, log.summary()
    assert not [e for e in events if e["event"] in ("action", "action_done", "alert_failed")]
    # the onboard fence is where the monitor's keep-out is
    y_ap = [p[2] for p in log.positions if p[0] <= t_breach][-1]
    assert NEAR_EDGE - 15 <= y_ap <= NEAR_EDGE + 15, y_ap
    assert breach["fence"] == "test/square", breach  # the monitor sees it inside, too

    speedup = _effective_speedup(log, warning["time"], t_breach)
    ground = statistics.mean(s for t, s in log.speeds if imminent["time"] - 1 <= t <= t_breach)
    lines = []
    for e in (warning, imminent):
        lead_wall = t_breach - e["time"]
        lead_flight = lead_wall * speedup
        lead_distance = (NEAR_EDGE - _y_at(e, frame)) / ground
        lines.append(
            f"{e['level']} {lead_wall:.3f} s wall = {lead_flight:.2f} s flight "
            f"(by distance {lead_distance:.2f} s; {NEAR_EDGE - _y_at(e, frame):.1f} m before the "
            f"edge; {e['reason']})"
        )
        assert lead_flight >= MIN_LEAD_S, lines[-1]
        assert lead_distance >= MIN_LEAD_S, lines[-1]
    assert imminent["time"] >= warning["time"]
    _replay_matches(flight, events)
    print(
        f"\nmonitor alert lead before ArduPilot's breach (effective speedup {speedup:.2f}, "
        f"{ground:.1f} m/s, ArduPilot breach at y={y_ap:.1f} m): "
        + "; ".join(lines)
        + f" | monitor: {_brief(events)}"
    )


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_enforcing_monitor_stops_the_vehicle_before_the_fence(link, sitl):
    """(b) enforce: IMMINENT -> brake (the link's hold) and the vehicle stops outside the
    square; ArduPilot never reports a breach. On each vehicle link."""
    results = {}

    async def body(flight: _Flight):
        log = flight.log
        t_action = await _until(
            "the monitor's brake",
            lambda: any(e["event"] == "action" for e in log.events),
            60,
            log,
            poll=0.01,
        )
        await _until(
            "a mode change after the brake",
            lambda: log.modes[-1][0] >= t_action - 0.5 and log.mode() != "GUIDED",
            5,
            log,
        )
        t_stop = await _until(
            "the vehicle stopped",
            lambda: log.speed() < STOPPED_MPS and log.speeds[-1][0] > t_action,
            30,
            log,
        )
        results["y_stop"] = log.positions[-1][2]
        t_end = await fence_reports(log, WATCH_AFTER_STOP, "FENCE_STATUS after stopping")
        results.update(t_action=t_action, t_stop=t_stop, t_end=t_end)

    flight = await _fly(sitl, True, body)
    log = flight.log
    events = list(log.events)
    actions = [e for e in events if e["event"] == "action"]
    assert actions and actions[0]["action"] == "brake", events
    imminent = _level_event(events, "IMMINENT")
    assert imminent and imminent["time"] == actions[0]["time"], events
    assert [e for e in events if e["event"] == "action_done" and e["action"] == "brake"], events
    assert not [e for e in events if e["event"] in ("action_failed", "alert_failed")], events
    assert not _level_event(events, "BREACH"), events
    assert not [e for e in events if e["event"] in ("action_withheld", "gps_glitch")], events

    # ArduPilot: no breach from takeoff to the end of the watch (30 s of its time), no RTL
    assert log.first_breach() is None, [f for _, f in log.fence if f["breach_status"]]
    assert all(f["breach_status"] == 0 for t, f in log.fence), log.summary()
    assert "RTL" not in [m for _, m in log.modes], log.summary()
    assert not [t for t, s in log.texts if "fence breached" in s.lower()], log.summary()

    after = [m for t, m in log.modes if t >= results["t_action"] - 0.5]
    onboard = [
        COPTER_MODES.get(m, m) for t, m in log.custom_modes if t >= results["t_action"] - 0.5
    ]
    # measured: either link's hold() puts ArduCopter in BRAKE (named HOLD, as MAVSDK does)
    assert onboard and onboard[-1] in ("LOITER", "BRAKE"), onboard
    farthest = max(p[2] for p in log.positions)
    final = log.positions[-1]
    assert farthest < NEAR_EDGE, f"flew to {farthest:.1f} m north (edge at {NEAR_EDGE:g} m)"
    assert abs(final[1]) < HALF_WIDTH and final[2] < NEAR_EDGE
    assert log.speed() < STOPPED_MPS, log.summary()
    assert abs(final[2] - results["y_stop"]) < 3.0, "drifted after stopping"
    y_imminent = _y_at(imminent, flight.frame)
    print(
        f"\nenforce ({link} link): IMMINENT/brake at y={y_imminent:.1f} m "
        f"({NEAR_EDGE - y_imminent:.1f} m before the edge), modes after it {after} "
        f"(ArduCopter {onboard}), stopped "
        f"{results['t_stop'] - results['t_action']:.2f} s wall after the action, farthest "
        f"y={farthest:.1f} m = {NEAR_EDGE - farthest:.1f} m short of the fence, final "
        f"y={final[2]:.1f} m, no breach for {results['t_end'] - results['t_stop']:.1f} s wall "
        f"after stopping | monitor: {_brief(events)} | {'; '.join(s for _, s in log.texts)}"
    )


def _replay_matches(flight, live_events):
    """Replaying the recorded telemetry through a fresh engine gives the same level changes
    (the engine is deterministic); ALPHAFENCE_RECORD_TRACE=path keeps the trace as JSON lines."""
    import dataclasses
    import os

    from alphafence.monitor.engine import Engine

    assert len(flight.trace) >= 50, len(flight.trace)
    engine = Engine(_monitor_fences(flight.frame), speedup_options(flight.sitl.speedup))
    replayed = [e for s in flight.trace for e in engine.step(s) if e["event"] == "level"]
    live = [e for e in live_events if e["event"] == "level"]
    assert [(e["time"], e["level"]) for e in replayed] == [(e["time"], e["level"]) for e in live]
    path = os.environ.get("ALPHAFENCE_RECORD_TRACE")
    if path:
        with open(path, "w", encoding="utf-8") as fh:
            for s in flight.trace:
                fh.write(json.dumps(dataclasses.asdict(s)) + "\n")
