"""Helpers shared by the SITL flight tests."""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from dataclasses import dataclass, field

import pytest
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.mavlink import ids
from alphafence.review.replay import speedup_options  # noqa: F401 (the flights' options)
from alphafence.vehicle.values import ardupilot_mode

# The exclusion square every fenced flight uses, metres east (x) / north (y) of home, and the
# altitude they fly at.
HALF_WIDTH = 50.0
NEAR_EDGE = 150.0
FAR_EDGE = 250.0
ALTITUDE = 20.0  # m above home
FENCE_STATUS_HZ = 2.0  # of the vehicle's own time: the rate fence_and_telemetry asks for
ARM_TIMEOUT = 60.0  # "Need Position Estimate" and friends: keep retrying this long


@dataclass
class FlightLog:
    """What the vehicle reported, each with its time.monotonic() of arrival; a test fills the
    lists it ``watch``es (each stream fills the list of its name), and ``events`` with the
    monitor's if it runs one."""

    frame: LocalFrame  # home's: positions are metres east (x) / north (y) of it
    texts: object = ()  # the Vehicle's STATUSTEXT deque, once connected
    positions: list = field(default_factory=list)  # (t, x east, y north, relative alt)
    speeds: list = field(default_factory=list)  # (t, horizontal speed m/s)
    modes: list = field(default_factory=list)  # (t, mode name), on change only: ArduPilot's
    # names on either link (MAVSDK's own read as ardupilot_mode reads them: HOLD = BRAKE)
    custom_modes: list = field(default_factory=list)  # (t, ArduCopter mode number), on change
    armed: list = field(default_factory=list)  # (t, bool), on change only
    fence: list = field(default_factory=list)  # (t, FENCE_STATUS fields)
    progress: list = field(default_factory=list)  # (t, current, total): the mission's
    events: list = field(default_factory=list)  # the monitor's (its EventLog's list)

    def mode(self):
        return self.modes[-1][1] if self.modes else None

    def speed(self):
        return self.speeds[-1][1] if self.speeds else math.inf

    def is_armed(self):
        return self.armed[-1][1] if self.armed else None

    def last_position(self, before=math.inf):
        earlier = [p for p in self.positions if p[0] <= before]
        return earlier[-1] if earlier else None

    def first_breach(self):
        """(t, FENCE_STATUS fields) of the first one reporting a breach, or None."""
        return next(((t, f) for t, f in self.fence if f["breach_status"] != 0), None)

    def summary(self) -> str:
        """For failure messages: the latest of each, mission progress and the monitor's events
        if there are any."""
        pos = self.last_position()
        where = f"x={pos[1]:.1f} y={pos[2]:.1f} alt={pos[3]:.1f}" if pos else "no position"
        modes = ", ".join(f"{m}@{t:.2f}" for t, m in self.modes[-6:])
        parts = [f"last position {where}", f"modes {modes}"]
        if self.progress:
            parts.append(f"mission progress {self.progress[-1][1:]}")
        parts.append(f"last FENCE_STATUS {self.fence[-1][1] if self.fence else 'none received'}")
        if self.events:
            events = "; ".join(
                f"{e['event']} {e.get('level') or e.get('action') or e.get('reason') or ''}"
                f"@{e['time']:.2f}"
                for e in list(self.events)[-10:]
            )
            parts.append(f"monitor: {events}")
        said = "; ".join(text for _, text in list(self.texts)[-8:])
        parts.append(f"vehicle said: {said}")
        return "; ".join(parts)


def watch(log: FlightLog, vehicle, *streams: str) -> list[asyncio.Task]:
    """Start the subscriptions named in ``streams``, each appending to the log's list of that
    name: "positions", "speeds", "modes" (names) and "armed" from the vehicle's telemetry,
    "progress" from its mission_raw, "fence" (FENCE_STATUS) and "custom_modes" (the
    autopilot's HEARTBEAT) from its ``messages``; the same on either link. Returns the tasks,
    for ``unwatch``. Nothing is asked of the vehicle here: the test sets the rates and asks for
    FENCE_STATUS itself."""
    frame = log.frame

    async def positions():
        async for p in vehicle.telemetry.subscribe_position():
            x, y = frame.to_local(p.longitude_deg, p.latitude_deg)
            log.positions.append((time.monotonic(), float(x), float(y), p.relative_altitude_m))

    async def speeds():
        async for v in vehicle.telemetry.subscribe_velocity_ned():
            log.speeds.append((time.monotonic(), math.hypot(v.north_m_s, v.east_m_s)))

    async def modes():
        async for mode in vehicle.telemetry.subscribe_flight_mode():
            if ardupilot_mode(mode.name) != log.mode():
                log.modes.append((time.monotonic(), ardupilot_mode(mode.name)))

    async def custom_modes():  # ArduPilot's own mode number
        sysid = await vehicle.system_id()
        async for message in vehicle.messages("HEARTBEAT"):
            f = message.fields
            if message.system_id != sysid or f["autopilot"] == ids.MAV_AUTOPILOT_INVALID:
                continue  # a ground station's (ours included) or another system's
            if not log.custom_modes or log.custom_modes[-1][1] != f["custom_mode"]:
                log.custom_modes.append((time.monotonic(), f["custom_mode"]))

    async def armed():
        async for is_armed in vehicle.telemetry.subscribe_armed():
            if is_armed != log.is_armed():
                log.armed.append((time.monotonic(), is_armed))

    async def fence():
        async for message in vehicle.messages("FENCE_STATUS"):
            log.fence.append((time.monotonic(), message.fields))

    async def progress():
        async for p in vehicle.mission_raw.subscribe_mission_progress():
            log.progress.append((time.monotonic(), p.current, p.total))

    watchers = {
        w.__name__: w for w in (positions, speeds, modes, custom_modes, armed, fence, progress)
    }
    return [asyncio.create_task(watchers[name]()) for name in streams]


async def unwatch(tasks):
    """Cancel ``watch``'s tasks and wait for them to end."""
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


async def ask_fence_status(vehicle, hz: float):
    """Ask the vehicle to stream FENCE_STATUS (MAVSDK's telemetry has none) with
    MAV_CMD_SET_MESSAGE_INTERVAL on the test's own connection."""
    result = await vehicle.command_long(
        ids.MAV_CMD_SET_MESSAGE_INTERVAL, ids.MAVLINK_MSG_ID_FENCE_STATUS, 1e6 / hz
    )
    assert result == ids.MAV_RESULT_ACCEPTED, f"FENCE_STATUS stream refused: result {result}"


async def upload_mission(vehicle, items):
    """Upload ``items`` (:class:`~alphafence.vehicle.values.RawItem`, seq 0 first) as the
    vehicle's mission with its mission_raw (MAVSDK's wants its own MissionItem: same fields)."""
    if vehicle.kind == "mavsdk":
        from mavsdk.plugins.mission_raw import MissionItem

        items = [MissionItem(*dataclasses.astuple(it)) for it in items]
    await vehicle.mission_raw.upload_mission(items)


async def until(what, predicate, timeout, log, poll=0.05):
    """Wait until ``predicate()`` is true, returning when; fail saying what the vehicle
    reported meanwhile (``log.summary()``)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"{what}: not within {timeout:g} s | {log.summary()}")
        await asyncio.sleep(poll)
    return time.monotonic()


async def fence_reports(log, seconds, what, timeout=60.0):
    """Wait for the FENCE_STATUS reports of ``seconds`` more of the vehicle's own time (they
    come at FENCE_STATUS_HZ of it, whatever the speedup): a watch kept on the vehicle's clock,
    failing saying ``what`` if they stop coming; returns when the last arrived."""
    n = len(log.fence) + math.ceil(seconds * FENCE_STATUS_HZ)
    return await until(what, lambda: len(log.fence) >= n, timeout, log)


async def retry(what, call, timeout):
    """``await call()`` until it succeeds (ArduPilot refuses arming until its checks pass;
    either link's refusal is an exception of its own)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return await call()
        except Exception as exc:
            if time.monotonic() > deadline:
                pytest.fail(f"{what} refused for {timeout:g} s: {exc}")
            await asyncio.sleep(1.0)


async def fence_and_telemetry(vehicle, log, items, poll=0.05, params="copter-rtl"):
    """The common start of a fenced SITL flight: upload the exclusion ``items`` and the
    ``params`` profile's parameters (each read back by the kit), stream positions and
    velocities at 10 Hz and FENCE_STATUS at FENCE_STATUS_HZ, and wait for the first of each;
    the vehicle must not be in breach on the ground at home."""
    from alphafence.vehicle.fence_transfer import upload_fence
    from alphafence.vehicle.params import PROFILES, apply_params

    report = await upload_fence(vehicle, items)
    assert report.verified and report.items == len(items)
    got = await apply_params(vehicle, PROFILES[params])
    action = PROFILES[params]["FENCE_ACTION"]
    assert got.values["FENCE_ENABLE"] == 1 and got.values["FENCE_ACTION"] == action

    await vehicle.telemetry.set_rate_position(10.0)
    await vehicle.telemetry.set_rate_velocity_ned(10.0)
    await ask_fence_status(vehicle, FENCE_STATUS_HZ)
    await until("a FENCE_STATUS", lambda: log.fence, 15, log, poll)
    await until("a position", lambda: log.positions, 15, log, poll)
    assert log.fence[-1][1]["breach_status"] == 0, "breached on the ground at home"


def square_local():
    """The exclusion square in the local frame (metres)."""
    return shapely.box(-HALF_WIDTH, NEAR_EDGE, HALF_WIDTH, FAR_EDGE)


def exclusion_items(frame: LocalFrame):
    """The square as an onboard exclusion polygon (4 items, 1e-7 degrees)."""
    from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem

    xs, ys = shapely.get_coordinates(square_local().exterior)[:-1].T
    lon, lat = frame.to_wgs84(xs, ys)
    return [
        FenceItem(POLYGON_EXCLUSION, 4.0, round(float(a), 7), round(float(b), 7))
        for a, b in zip(lon, lat)
    ]


async def take_off(action, log, altitude=ALTITUDE, poll=0.05):
    """Arm (retrying while ArduPilot refuses), take off in GUIDED and climb to 90 % of
    ``altitude``; returns (takeoff command time, climbed time)."""
    await action.set_takeoff_altitude(altitude)
    await retry("arming", action.arm, ARM_TIMEOUT)
    t_takeoff = time.monotonic()
    await retry("takeoff", action.takeoff, 15)
    t_up = await until(
        "climb to 90% of the takeoff altitude",
        lambda: log.positions[-1][3] >= 0.9 * altitude,
        60,
        log,
        poll,
    )
    assert log.mode() == "GUIDED", f"not in GUIDED: {log.mode()}"
    return t_takeoff, t_up


async def within(coro, timeout, log):
    """``await coro``, failing the test with what the vehicle reported if it takes over
    ``timeout`` wall seconds."""
    try:
        return await asyncio.wait_for(coro, timeout)
    except asyncio.TimeoutError:
        pytest.fail(f"the flight took over {timeout:g} s | {log.summary()}")
