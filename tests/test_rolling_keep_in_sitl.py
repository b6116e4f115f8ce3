"""The rolling onboard fence with several keep-in areas, in a real flight (copter SITL, Egham):
a keep-in area round home, a second 800 m east and a corridor joining them. The monitor runs
with ``--onboard rolling``; once it has uploaded its first fence the ``copter-rtl`` parameters
are set (ArduPilot enforces the rolling fence: RTL on a breach) and the copter flies from the
first area along the corridor into the second. Every upload of more than one inclusion sets
FENCE_OPTIONS' union bit and reads it back (ArduPilot 4.7 reads it), the vehicle reports no
breach on the way, and no RTL."""

from __future__ import annotations

import asyncio
import math

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.inclusions import FENCE_OPTIONS, union_of
from alphafence.mavlink.storage import PROFILES
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import RollingOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import read_params
from tests.sitl_flight import (
    ALTITUDE,
    FlightLog,
    ask_fence_status,
    speedup_options,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

pytestmark = pytest.mark.sitl
SPEEDUP = 5
SPEED = 8.0
ROLLING = RollingOptions(profile=PROFILES["copter"], speed_mps=SPEED, upload_budget_s=15.0)
# metres east, north of home: two keep-in areas and the corridor between them
AREAS = {"west": (-150, -150, 150, 150), "corridor": (100, -50, 750, 50),
         "east": (700, -150, 1000, 150)}  # fmt: skip
# ArduPilot refuses a GUIDED target outside its fence, and the rolling fence holds only the
# areas within reach: the copter is sent on in steps, each inside what it holds where it is
WAYPOINTS = [(300.0, 0.0), (550.0, 0.0), (850.0, 0.0)]


async def fly_to(vehicle, sitl, frame, log, goal):
    """GUIDED to ``goal`` (metres east, north of home), the target sent again every 10 s until
    the copter is within 15 m of it (the fence may not allow it yet when first sent)."""
    lon, lat = frame.to_wgs84(*goal)

    def there():
        _, x, y, _ = log.positions[-1]
        return math.hypot(x - goal[0], y - goal[1]) < 15.0

    for _ in range(15):
        await vehicle.action.goto_location(float(lat), float(lon), sitl.home.alt + ALTITUDE, 0.0)
        await vehicle.action.set_current_speed(SPEED)
        try:
            await asyncio.wait_for(until(f"reach {goal}", there, 1e9, log), 10.0)
            return
        except asyncio.TimeoutError:
            continue
    raise AssertionError(f"never reached {goal}: {log.summary()}")


@pytest.mark.parametrize("sitl", [{"home": "egham", "speedup": SPEEDUP}], indirect=True)
async def test_the_rolling_fence_flies_from_one_keep_in_area_to_the_other(sitl):
    from alphafence.vehicle.params import PROFILES as PARAMS
    from alphafence.vehicle.params import apply_params

    frame = LocalFrame(sitl.home.lon, sitl.home.lat)
    records = [FenceRecord(f"keep-in/{k}", "keep_in", frame.geom_to_wgs84(shapely.box(*b)))
               for k, b in AREAS.items()]  # fmt: skip
    fences = FenceSet(records, frame=frame, keep_in_union=True)
    log = FlightLog(frame)
    monitor_log = EventLog()
    log.events = monitor_log.events
    options_read = []

    async def flight():
        async with open_vehicle(sitl.connection_url) as vehicle:
            log.texts = vehicle.texts
            watchers = watch(log, vehicle, "positions", "modes", "fence")
            options = speedup_options(SPEEDUP, onboard="rolling", rolling=ROLLING)
            monitor = Monitor(vehicle, fences, options, monitor_log)
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            try:
                await vehicle.telemetry.set_rate_position(10.0)
                uploaded = lambda: [e for e in log.events if e["event"] == "onboard_upload"]  # noqa: E731
                await until("the first rolling fence", uploaded, 60, log)
                await apply_params(vehicle, PARAMS["copter-rtl"])
                await ask_fence_status(vehicle, 2.0)
                await until("a FENCE_STATUS", lambda: log.fence, 15, log)
                await take_off(vehicle.action, log)
                for goal in WAYPOINTS:  # each within the fence the vehicle holds there
                    await fly_to(vehicle, sitl, frame, log, goal)
                options_read.append((await read_params(vehicle, [FENCE_OPTIONS]))[FENCE_OPTIONS])
                assert not task.done(), "the monitor stopped by itself"
            finally:
                stop.set()
                await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 10)
                await unwatch(watchers)

    await within(flight(), 240.0, log)
    uploads = [e for e in log.events if e["event"] == "onboard_upload"]
    bad = [e for e in log.events if e["event"] in ("onboard_upload_failed", "onboard_behind")]
    assert not bad, bad
    assert uploads and all(u["verified"] for u in uploads), uploads
    several = [u for u in uploads if "inclusions" in u]
    assert several and all(u["inclusions"] == "union" for u in several), uploads
    assert union_of(options_read[0])  # set and read back, and still set at the end
    assert log.fence and all(f["breach_status"] == 0 for _, f in log.fence), log.summary()
    assert "RTL" not in [m for _, m in log.modes], log.summary()
