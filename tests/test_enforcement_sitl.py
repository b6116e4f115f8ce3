"""The uploaded fence is enforced by ArduPilot itself: real copter SITL, a flight into it.

An exclusion square (100 m x 100 m, near edge 150 m north of home) is uploaded with the kit's
own uploader, the ``copter-rtl`` parameters are applied (FENCE_ACTION 1: RTL or land), and the
copter takes off in GUIDED to 20 m and is sent to a point 400 m north, *beyond* the square (a
GUIDED target inside an exclusion zone is silently ignored, so the track has to cross it). The
test asserts that ArduPilot reports the breach (FENCE_STATUS breach_status 1, a boundary
breach, "Polygon fence breached") where the square is, switches to RTL within a few seconds of
it, never gets across the square, and flies back out of it.

MAVSDK's telemetry has no FENCE_STATUS, so it is read as a MAVLink message (the Vehicle's
``messages``, on either link) on the same connection (only one program can own the SITL UDP
port), after asking for it with MAV_CMD_SET_MESSAGE_INTERVAL. ArduPilot streams nothing by
default on this link: positions and velocities are asked for with ``set_rate_*`` too.

Measured (egham, speedup 5, 2-core machine; 6 runs, two of them side by side; wall-clock
seconds, x5 for sim time): arming succeeds at the first try (the fixture already waited for a
position estimate); takeoff command to 18 m 2.44 s; goto to breach 3.50 s; takeoff command to
breach 5.94-5.96 s; ground speed 10.0 m/s; the last position before the breach report
149.4-150.1 m north, i.e. the breach is declared at the square's edge itself (FENCE_MARGIN does
not move it); flight mode RTL reported 0.006-0.012 s after the FENCE_STATUS breach (the same
scheduler tick: ArduPilot switches mode as it declares the breach); the STATUSTEXTs "Polygon
fence breached", "Manual recovery started", later "Fence breach cleared"; farthest north
171.2-171.8 m (about 21 m past the edge); back out of the square and FENCE_STATUS clear
2.15-2.20 s after the breach. The test takes about 17 s wall, SITL start included.
"""

from __future__ import annotations

import time

import pytest

from alphafence.geo.frame import LocalFrame
from alphafence.vehicle.link import open_vehicle
from tests.sitl_flight import (
    ALTITUDE,
    FAR_EDGE,
    NEAR_EDGE,
    FlightLog,
    exclusion_items,
    fence_and_telemetry,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

EGHAM = {"home": "egham", "speedup": 5}

# metres north of home (the square: tests/sitl_flight.py)
TARGET_NORTH = 400.0  # beyond the square: GUIDED ignores targets inside an exclusion zone
SPEED = 10.0  # m/s: WPNAV_SPEED's default, also asked for with DO_CHANGE_SPEED

WALL_TIMEOUT = 120.0  # the whole flight, from connecting to the vehicle
MODE_SWITCH_MAX = 3.0  # wall seconds between the breach report and RTL (measured: ~0)

FENCE_BREACH_BOUNDARY = 3


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_uploaded_exclusion_is_enforced_with_rtl(sitl):
    log = FlightLog(LocalFrame(sitl.home.lon, sitl.home.lat))
    await within(_fly_into_the_fence(sitl, log), WALL_TIMEOUT, log)


async def _fly_into_the_fence(sitl, log: FlightLog):
    home = sitl.home
    frame = log.frame
    async with open_vehicle(sitl.connection_url) as vehicle:
        log.texts = vehicle.texts
        action = vehicle.action
        watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence")
        try:
            # -- the fence and its parameters, each read back by the kit
            await fence_and_telemetry(vehicle, log, exclusion_items(frame))

            # -- arm and take off in GUIDED (named OFFBOARD, as MAVSDK names it)
            t_takeoff, t_up = await take_off(action, log)
            assert not log.first_breach(), "breach before the vehicle was sent anywhere"

            # -- across the square: a target beyond it, 400 m north, at 10 m/s
            lon, lat = frame.to_wgs84(0.0, TARGET_NORTH)
            await action.set_current_speed(SPEED)
            await action.goto_location(float(lat), float(lon), home.alt + ALTITUDE, 0.0)
            t_goto = time.monotonic()

            # (a) ArduPilot reports the breach, at the square's near edge
            await until("FENCE_STATUS breach", log.first_breach, 60, log, poll=0.01)
            t_breach, status = log.first_breach()
            assert status["breach_type"] == FENCE_BREACH_BOUNDARY, status
            assert status["breach_count"] >= 1, status
            _, x, y, alt = log.last_position(before=t_breach)
            assert abs(x) < 10 and NEAR_EDGE - 15 <= y <= NEAR_EDGE + 15, (x, y)
            assert alt > 0.8 * ALTITUDE, alt
            speed = max(s for t, s in log.speeds if t_goto <= t <= t_breach)
            assert speed > 0.8 * SPEED, f"only {speed:.1f} m/s on the way in"

            # (b) ... and switches to the configured action, RTL, within a few seconds
            await until(
                "RTL after the breach",
                lambda: log.mode() == "RETURN_TO_LAUNCH",
                MODE_SWITCH_MAX,
                log,
                poll=0.01,
            )
            t_rtl = next(t for t, m in log.modes if m == "RETURN_TO_LAUNCH")
            assert abs(t_rtl - t_breach) <= MODE_SWITCH_MAX
            await until(
                "the breach STATUSTEXT",
                lambda: any(
                    "fence breached" in text.lower() for t, text in vehicle.texts if t >= t_takeoff
                ),
                5,
                log,
            )

            # the vehicle never got across the square (it overshoots the edge by about 20 m at
            # 10 m/s), and RTL brings it back out of it
            t_out = await until(
                "back south of the square",
                lambda: log.positions[-1][2] < NEAR_EDGE - 10,
                30,
                log,
            )
            t_clear = await until(
                "FENCE_STATUS breach cleared",
                lambda: log.fence[-1][1]["breach_status"] == 0,
                30,
                log,
            )
            farthest = max(p[2] for p in log.positions)
            assert farthest < NEAR_EDGE + 40 < FAR_EDGE, f"flew {farthest:.0f} m north"
            assert log.mode() == "RETURN_TO_LAUNCH", log.mode()
            said = [text for t, text in vehicle.texts if t >= t_takeoff]

            print(
                f"\nenforcement: takeoff->{ALTITUDE * 0.9:.0f} m {t_up - t_takeoff:.2f} s, "
                f"goto->breach {t_breach - t_goto:.2f} s, takeoff->breach "
                f"{t_breach - t_takeoff:.2f} s, breach at y={y:.1f} m, {speed:.1f} m/s, "
                f"RTL {t_rtl - t_breach:+.3f} s after the breach, farthest {farthest:.1f} m, "
                f"out {t_out - t_breach:.2f} s and cleared {t_clear - t_breach:.2f} s after it, "
                f"speedup {sitl.speedup:g} | {'; '.join(said)}"
            )
        finally:
            await unwatch(watchers)
