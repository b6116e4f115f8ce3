"""ArduPilot's own verdict on inclusions and exclusions, against the model and the monitor.

A fence of several inclusion polygons and circles with exclusions inside them is uploaded
with the kit's ``upload`` (which sets FENCE_OPTIONS bit 1 for more than one inclusion) and a
preset; the copter at home, inside one inclusion only, must arm. Then it flies to sampled
positions (the fence reporting only, FENCE_ACTION 0) and at each, under FENCE_OPTIONS 0
(intersection) and 2 (union), the vehicle's own FENCE_STATUS breach_status is compared with
tests/ardupilot_model.py's ``breached`` and with the monitor's reading of the fence it
downloads (``OnboardLayer``). Legs are flown with the fence disabled (GUIDED ignores a target
the fence forbids), re-enabled at each position before it is read.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.inclusions import FENCE_OPTIONS
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    FenceItem,
)
from alphafence.monitor.onboard import OnboardLayer
from alphafence.vehicle.fence_transfer import download_fence
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import apply_params

from .ardupilot_model import breached
from .sitl_flight import (
    ALTITUDE,
    FlightLog,
    ask_fence_status,
    fence_reports,
    take_off,
    until,
    unwatch,
    watch,
)

pytestmark = pytest.mark.sitl
EGHAM = {"home": "egham", "speedup": 5, "param_values": {"AVOID_ENABLE": 0}}
SPEED = 15.0  # m/s between the samples: 1.7 km of legs in less simulated time

# metres east, north of home: two inclusion squares overlapping (home in the first only), an
# inclusion circle east of them, an exclusion square inside the first and a circle in the circle
A = shapely.box(-200, -200, 200, 200)
C = shapely.box(100, -100, 500, 300)
B = (700.0, 0.0, 150.0)
E1 = shapely.box(-150, 90, -90, 150)
E2 = (700.0, 0.0, 40.0)
# where the copter is read: in A only, A and C, C only, B only, in none, inside E1 (excluded)
SAMPLES = [(0, 0), (150, 50), (400, 100), (700, 100), (-50, 300), (-120, 120)]


def fence_items(frame):
    def polygon(cmd, box):
        xs, ys = shapely.get_coordinates(box.exterior)[:-1].T
        lon, lat = frame.to_wgs84(xs, ys)
        return [FenceItem(cmd, float(len(xs)), round(float(a), 7), round(float(b), 7))
                for a, b in zip(lon, lat)]  # fmt: skip

    def circle(cmd, c):
        lon, lat = frame.to_wgs84(c[0], c[1])
        return [FenceItem(cmd, c[2], round(float(lon), 7), round(float(lat), 7))]

    return (polygon(POLYGON_INCLUSION, A) + polygon(POLYGON_INCLUSION, C)
            + circle(CIRCLE_INCLUSION, B) + polygon(POLYGON_EXCLUSION, E1)
            + circle(CIRCLE_EXCLUSION, E2))  # fmt: skip


def monitor_breach(layer, frame, lon, lat):
    """The monitor's verdict: inside an exclusion, or outside the inclusions by the
    vehicle's rule, at ``(lon, lat)``."""
    x, y = layer.frame.to_local(lon, lat)
    check = layer.index.check(float(x), float(y), ALTITUDE, 0.0, 0.0, 1.0)
    held = [layer.fence(k) for k in check.inside_keep_out]
    return bool(check.outside_keep_in) or any(not f.inclusion for f in held)


async def status_after(vehicle, log, **params):
    """Set ``params`` and return the breach_status of a FENCE_STATUS sent a report later."""
    await apply_params(vehicle, params)
    await fence_reports(log, 1.0, f"FENCE_STATUS after {params}")
    return int(log.fence[-1][1]["breach_status"])


async def fly_to(vehicle, sitl, frame, log, x, y):
    """GUIDED to ``(x, y)`` metres from home at SPEED, until there (within 3 m). The target is
    sent again each time the vehicle has not arrived after what the leg takes at 5 m/s: ArduPilot
    ignores a target its fence forbids, and it takes a moment to see FENCE_ENABLE change."""
    lon, lat = frame.to_wgs84(x, y)

    def there():
        return np.hypot(log.positions[-1][1] - x, log.positions[-1][2] - y) < 3.0

    for _ in range(12):
        await vehicle.action.goto_location(float(lat), float(lon), sitl.home.alt + ALTITUDE)
        await vehicle.action.set_current_speed(SPEED)  # after the goto, which resets it
        leg = np.hypot(log.positions[-1][1] - x, log.positions[-1][2] - y)
        try:
            await asyncio.wait_for(until(f"reach {x}, {y}", there, 1e9, log), 10.0 + leg / 5.0)
            return
        except asyncio.TimeoutError:
            continue
    pytest.fail(f"never reached {x}, {y} | {log.summary()}")


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_vehicle_reads_inclusions_as_the_model_and_the_monitor(sitl, tmp_path):
    from alphafence.cli import main
    from alphafence.fencefiles.qgc_plan import dumps, plan_document

    frame = LocalFrame(sitl.home.lon, sitl.home.lat)
    items = fence_items(frame)
    plan = tmp_path / "areas.plan"
    plan.write_text(dumps(plan_document(items)))
    argv = ["upload", str(plan), "--connect", sitl.connection_url, "--params", "copter-report",
            "--allow-unsigned"]  # fmt: skip
    assert await asyncio.to_thread(main, argv) == 0  # sets FENCE_OPTIONS bit 1 for 3 inclusions

    log = FlightLog(frame)
    async with open_vehicle(sitl.connection_url, link="pymavlink") as vehicle:
        got = await download_fence(vehicle)
        layers = {u: OnboardLayer.from_items(got, frame, union=u) for u in (False, True)}
        tasks = watch(log, vehicle, "positions", "modes", "armed", "fence")
        try:
            await vehicle.telemetry.set_rate_position(10.0)
            await ask_fence_status(vehicle, 2.0)
            await until("a FENCE_STATUS", lambda: log.fence, 30, log)
            assert (await status_after(vehicle, log)) == 0  # at home in A: the upload set the union
            await take_off(vehicle.action, log)  # arms: home is inside A (union)
            rows = []
            for x, y in SAMPLES:
                await apply_params(vehicle, {"FENCE_ENABLE": 0})
                await fly_to(vehicle, sitl, frame, log, x, y)
                for union in (False, True):
                    status = await status_after(vehicle, log, FENCE_ENABLE=1,
                                                **{FENCE_OPTIONS: 2 if union else 0})  # fmt: skip
                    _, px, py, _ = log.positions[-1]
                    plon, plat = frame.to_wgs84(px, py)
                    model = bool(breached(got, [plon], [plat], union)[0])
                    monitor = monitor_breach(layers[union], frame, plon, plat)
                    rows.append(((x, y), union, bool(status), model, monitor))
        finally:
            await unwatch(tasks)
    table = "\n".join(str(r) for r in rows)
    assert all(r[2] == r[3] == r[4] for r in rows), (
        f"(where, union, SITL, model, monitor):\n{table}"
    )
    verdict = {(r[0], r[1]): r[2] for r in rows}
    # the cases the samples were chosen for: each is a verdict the vehicle gave
    assert verdict[((0, 0), True)] is False and verdict[((0, 0), False)] is True
    assert verdict[((150, 50), True)] is False and verdict[((-50, 300), True)] is True
    assert verdict[((-120, 120), True)] is True and verdict[((700, 100), True)] is False
