"""Helpers shared by the SITL flight tests."""

import asyncio
import json
import time

import pytest

MAV_CMD_SET_MESSAGE_INTERVAL = 511
FENCE_STATUS_ID = 162


async def ask_fence_status(direct, hz: float):
    """Ask the vehicle to stream FENCE_STATUS (MAVSDK's telemetry has none) through MAVSDK's
    mavlink_direct plugin on the test's own connection."""
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    fields = {
        "target_system": 1,
        "target_component": 1,
        "command": MAV_CMD_SET_MESSAGE_INTERVAL,
        "confirmation": 0,
        "param1": FENCE_STATUS_ID,
        "param2": 1e6 / hz,
        "param3": 0,
        "param4": 0,
        "param5": 0,
        "param6": 0,
        "param7": 0,
    }
    ack = await direct.send_command(MavlinkMessage("COMMAND_LONG", 0, 0, 1, 1, json.dumps(fields)))
    result = json.loads(ack.fields_json or "{}").get("result")
    assert result == 0, f"FENCE_STATUS stream refused: {ack.fields_json!r}"


async def until(what, predicate, timeout, log, poll=0.05):
    """Wait until ``predicate()`` is true, returning when; fail saying what the vehicle
    reported meanwhile (``log.summary()``)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"{what}: not within {timeout:g} s | {log.summary()}")
        await asyncio.sleep(poll)
    return time.monotonic()


async def retry(what, call, timeout):
    """``await call()`` until it succeeds (ArduPilot refuses arming until its checks pass)."""
    from mavsdk.plugins.action import ActionError

    deadline = time.monotonic() + timeout
    while True:
        try:
            return await call()
        except ActionError as exc:
            if time.monotonic() > deadline:
                pytest.fail(f"{what} refused for {timeout:g} s: {exc}")
            await asyncio.sleep(1.0)


def speedup_options(speedup: float, **kw):
    """MonitorOptions for SITL at ``speedup``: the engine's own durations are wall seconds
    (telemetry arrival times) while speeds and the braking model are the vehicle's, so the
    wall-clock ones are scaled. Unscaled, at speedup 5, 10 m/s is 50 m/s per wall second,
    within arrival jitter of ``max_speed_mps``, and ``backoff_s`` lasts 75 s of flight."""
    from kit.monitor.engine import MonitorOptions

    o = MonitorOptions(**kw)
    o.hold_s /= speedup
    o.backoff_s /= speedup
    o.stale_s /= speedup
    o.max_speed_mps *= speedup
    return o
