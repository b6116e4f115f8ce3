"""The monitor sees the fence ArduPilot enforces (copter SITL, Malta): the issue's flight.

The Malta fences are built from the shared extract (``alphafence build``, alpha, default rules)
and compiled for the 5 km box around the airport with the default copter profile
(``alphafence compile --bbox 14.4583,35.8685,14.5137,35.9135 --profile copter``): 560 bytes
for about a hundred fences, so neighbours are merged into circles that swallow whole
neighbourhoods. From the issue's home (35.89098 N, 14.48600 E) the copter is sent in GUIDED at
10 m/s toward the nearest full-resolution keep-out fence, with the monitor running
(``enforce``, the onboard layer on, as ``alphafence monitor --enforce`` runs it, on the
test's own connection). The compiled fence is uploaded to SITL with
``alphafence upload ... --params copter-rtl`` (FENCE_ACTION 1: RTL on a breach).

Where the copter starts: on the line from the issue's home to the nearest point of that fence,
moved back along it so that there are ``RUN_UP_M`` of straight flight before the first
onboard fence (from the issue's home itself a merged circle begins about 65 m away: the copter
would not reach 10 m/s). SITL's home is that start point. The goto target is the first point
on the line beyond the onboard fence that is clear of every fence (ArduPilot ignores a GUIDED
target inside an exclusion zone).

The test asserts that the monitor loaded the vehicle's fence at start (every item as
compiled), that it raised IMMINENT for the onboard fence (naming its item, and saying
``onboard_only`` where no full-resolution fence is within 2 m of where the track meets it),
braked, and that the copter stopped outside every onboard and every full-resolution fence,
with breach_status 0 in every FENCE_STATUS, no RTL and no "fence breached" text.

Measured (speedup 5, 3 runs; the test prints them): 44 onboard items (a polygon and 40
circles), forbidding 14.7 km² that no full-resolution keep-out does; the nearest keep-out
(power/way/531608386) lies 445 m along the leg, the merged circle over it 200 m (245 m before
it); IMMINENT (onboard_only, "onboard exclusion circle 1 (item 4)") 36.1-36.7 m before the
circle at 10.0 m/s (stopping distance 36.8 m); the copter stopped 15.4-16.0 m short of the
circle, 261 m short of the real fence; no ArduPilot breach. About 30 s wall, SITL start
included.
"""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.onboard import SAME_FENCE_M, OnboardLayer
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.fence_transfer import download_fence, same_items
from alphafence.vehicle.link import open_vehicle
from tests.sitl_flight import (
    ALTITUDE,
    FENCE_STATUS_HZ,
    FlightLog,
    ask_fence_status,
    fence_reports,
    speedup_options,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

BOX = "14.4583,35.8685,14.5137,35.9135"
ISSUE_HOME = (14.48600, 35.89098)  # lon, lat
SPEEDUP = 5
SPEED = 10.0
RUN_UP_M = 200.0  # straight flight before the first onboard fence (10 m/s needs about 20 m)
CLEAR_M = 30.0  # the start and the target keep this far from every fence
STOPPED_MPS = 0.3
WATCH_AFTER_STOP = 20.0  # seconds of the vehicle's time (FENCE_STATUS) of no breach after stopping
WALL_TIMEOUT = 150.0


@pytest.fixture(scope="module")
def malta_compiled(malta, tmp_path_factory):
    """The Malta fences and the copter's compiled fence for the box, as the CLI makes them."""
    from alphafence.cli import main

    out = tmp_path_factory.mktemp("malta-onboard")
    fences, plan = out / "fences.geojson", out / "onboard.plan"
    assert main(["build", str(malta), "-o", str(fences)]) == 0
    args = ["compile", str(fences), "--bbox", BOX, "--profile", "copter", "-o", str(plan)]
    assert main(args) == 0
    return fences, plan


class Leg:
    """The straight leg at the nearest keep-out fence, in metres of a frame at its start."""

    def __init__(self, fences_path, items):
        records = read_fences(fences_path)
        keep_out = [r for r in records if r.kind == "keep_out"]
        issue = LocalFrame(*ISSUE_HOME)
        local = issue.geom_to_local(np.array([r.geometry for r in keep_out], dtype=object))
        origin = shapely.Point(0.0, 0.0)
        k = int(np.argmin(shapely.distance(origin, local)))
        self.nearest = keep_out[k].site_id
        near = shapely.shortest_line(origin, local[k]).coords[1]
        d = math.hypot(*near)
        ux, uy = near[0] / d, near[1] / d
        onboard = OnboardLayer.from_items(items, issue)
        exclusions = [
            onboard.index.local[j]
            for j in range(len(onboard.index.records))
            if onboard.index.records[j].kind == "keep_out"
        ]
        ray = shapely.LineString([(0.0, 0.0), (ux * 5000.0, uy * 5000.0)])
        entry = min(
            float(origin.distance(ray.intersection(g))) for g in exclusions if g.intersects(ray)
        )
        back = max(0.0, RUN_UP_M - entry)
        self.start = issue.to_wgs84(-ux * back, -uy * back)
        # from here on, metres in a frame at the start (SITL's home)
        self.frame = LocalFrame(*self.start)
        self.u = (ux, uy)
        self.real = FenceSet(records, frame=self.frame)
        self.onboard = OnboardLayer.from_items(items, self.frame)
        self.exclusions = [
            self.onboard.index.local[j]
            for j in range(len(self.onboard.index.records))
            if self.onboard.index.records[j].kind == "keep_out"
        ]
        self.keep_out = [g for g, r in zip(self.real.local, records) if r.kind == "keep_out"]
        self.entry_m = entry + back  # along the leg, from the start
        self.real_m = d + back
        clear = self.clearance(0.0)
        assert clear >= CLEAR_M, f"the start is {clear:.0f} m from a fence"
        hit = (ux * self.entry_m, uy * self.entry_m)
        self.onboard_only = self.real_distance(*hit) > SAME_FENCE_M
        along = self.entry_m
        while self.clearance(along) < CLEAR_M:
            along += 5.0
            assert along < 5000.0, "no clear target on the leg"
        self.target_m = along + 20.0
        self.target = self.frame.to_wgs84(ux * self.target_m, uy * self.target_m)

    def point(self, along):
        return shapely.Point(self.u[0] * along, self.u[1] * along)

    def clearance(self, along) -> float:
        p = self.point(along)
        return float(min(shapely.distance(p, self.exclusions + self.keep_out)))

    def real_distance(self, x, y) -> float:
        return float(min(shapely.distance(shapely.Point(x, y), self.keep_out)))

    def onboard_distance(self, x, y) -> float:
        return float(min(shapely.distance(shapely.Point(x, y), self.exclusions)))


async def test_the_enforcing_monitor_stops_before_the_fence_the_vehicle_enforces(
    malta_compiled, sitl_factory
):
    from alphafence.cli import main

    fences_path, plan = malta_compiled
    compiled = read_plan_fence(plan)
    leg = Leg(fences_path, compiled)
    lon0, lat0 = (float(v) for v in leg.start)
    sitl = await sitl_factory(home=f"{lat0:.7f},{lon0:.7f},80,0", speedup=SPEEDUP)
    upload = ["upload", str(fences_path), "--connect", sitl.connection_url, "--allow-unsigned"]
    upload += ["--bbox", BOX, "--profile", "copter", "--params", "copter-rtl"]
    assert await asyncio.to_thread(main, upload) == 0

    log = FlightLog(leg.frame)
    monitor_log = EventLog()
    log.events = monitor_log.events
    results = {}

    async def flight():
        async with open_vehicle(sitl.connection_url) as vehicle:
            log.texts = vehicle.texts
            assert same_items(compiled, await download_fence(vehicle)) == []
            watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence")
            stop = asyncio.Event()
            monitor = Monitor(
                vehicle,
                FenceSet.from_geojson(fences_path),
                speedup_options(SPEEDUP, enforce=True),
                monitor_log,
            )
            task = asyncio.create_task(monitor.run(stop))
            try:
                await vehicle.telemetry.set_rate_position(10.0)
                await vehicle.telemetry.set_rate_velocity_ned(10.0)
                await ask_fence_status(vehicle, FENCE_STATUS_HZ)
                await until("the monitor's onboard layer", lambda: _loaded(log.events), 30, log)
                await until("a FENCE_STATUS", lambda: log.fence, 15, log)
                await take_off(vehicle.action, log)
                lon, lat = leg.target
                await vehicle.action.set_current_speed(SPEED)
                await vehicle.action.goto_location(
                    float(lat), float(lon), sitl.home.alt + ALTITUDE, 0.0
                )
                results["t_goto"] = time.monotonic()
                t_action = await until(
                    "the monitor's brake",
                    lambda: any(e["event"] == "action" for e in log.events),
                    60,
                    log,
                    poll=0.01,
                )
                results["t_stop"] = await until(
                    "the vehicle stopped",
                    lambda: log.speed() < STOPPED_MPS and log.speeds[-1][0] > t_action + 0.2,
                    30,
                    log,
                )
                results["t_end"] = await fence_reports(  # ArduPilot must stay quiet meanwhile
                    log, WATCH_AFTER_STOP, "FENCE_STATUS after stopping"
                )
                assert not task.done(), "the monitor stopped by itself"
                results["checks"] = monitor.engine.checks
            finally:
                stop.set()
                await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 10)
                await unwatch(watchers)

    await within(flight(), WALL_TIMEOUT, log)
    events = list(log.events)
    loaded = _loaded(events)
    assert loaded["items"] == len(compiled) and loaded["cause"] == "start", loaded
    imminent = next(e for e in events if e["event"] == "level" and e["level"] == "IMMINENT")
    action = next(e for e in events if e["event"] == "action")
    assert action["action"] == "brake" and action["time"] == imminent["time"], events
    assert imminent["onboard"] and imminent["items"], imminent  # the onboard item, named
    assert imminent["onboard_only"] is leg.onboard_only, imminent
    if leg.onboard_only:
        assert imminent["fence"].startswith("onboard exclusion "), imminent
    assert not [e for e in events if e["event"] == "level" and e["level"] == "BREACH"], events
    assert not [e for e in events if e["event"] in ("action_failed", "onboard_failed")], events

    # ArduPilot: no breach from takeoff to the end, no RTL, no breach text
    assert log.fence and all(f["breach_status"] == 0 for _, f in log.fence), log.summary()
    assert "RTL" not in [m for _, m in log.modes], log.summary()
    assert not [t for t, s in log.texts if "fence breached" in s.lower()], log.summary()

    # every position outside every onboard and every full-resolution fence
    flown = [p for p in log.positions if p[0] >= results["t_goto"]]
    assert len(flown) >= 20, len(flown)
    onboard_gap = min(leg.onboard_distance(x, y) for _, x, y, _ in flown)
    real_gap = min(leg.real_distance(x, y) for _, x, y, _ in flown)
    assert onboard_gap > 0 and real_gap > 0, (onboard_gap, real_gap)
    final = log.positions[-1]
    assert log.speed() < STOPPED_MPS, log.summary()
    farthest = max(x * leg.u[0] + y * leg.u[1] for _, x, y, _ in flown)
    x_i, y_i = leg.frame.to_local(imminent["lon"], imminent["lat"])
    at_imminent = float(x_i) * leg.u[0] + float(y_i) * leg.u[1]
    top = max(s for t, s in log.speeds if results["t_goto"] <= t <= action["time"])
    print(
        f"\nonboard layer: {loaded['items']} items {loaded['fences']}, "
        f"{loaded['forbidden_beyond_m2'] / 1e6:.2f} km² forbidden beyond the real fences; "
        f"nearest keep-out {leg.nearest}: real fence {leg.real_m:.0f} m along the leg, onboard "
        f"fence {leg.entry_m:.0f} m ({leg.real_m - leg.entry_m:.0f} m before it); IMMINENT at "
        f"{at_imminent:.1f} m ({imminent['fence']}, onboard_only {imminent['onboard_only']}, "
        f"{imminent['distance_m']} m ahead, stopping {imminent['stopping_m']} m, top speed "
        f"{top:.1f} m/s); farthest {farthest:.1f} m: {leg.entry_m - farthest:.1f} m short of "
        f"the onboard fence, {leg.real_m - farthest:.1f} m short of the real one; least gap "
        f"to any onboard fence {onboard_gap:.1f} m, to any real fence {real_gap:.1f} m; final "
        f"x={final[1]:.1f} y={final[2]:.1f}; no ArduPilot breach for "
        f"{results['t_end'] - results['t_stop']:.1f} s wall after stopping; "
        f"{results['checks']} checks"
    )


def _loaded(events):
    return next((e for e in events if e["event"] == "onboard_fence"), None)
