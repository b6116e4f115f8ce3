"""Reboot the autopilot, only while it is disarmed, and wait until it is back.

The reboot is a COMMAND_LONG ``MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN`` with param1 = 1 (the
autopilot alone: MAVSDK's own reboot also asks for the companion computer, which on a Navio2
is the Pi this runs on). ArduPilot refuses it while armed and otherwise acknowledges it,
then restarts: SITL re-executes itself (same process and working directory, new sockets);
on Linux boards (the Navio2) the process exits and its service must start it again.

That the vehicle came back *rebooted* is read from the vehicle itself: SYSTEM_TIME's
``time_boot_ms``, asked for at each heartbeat, falls below what it was before the command.
A vehicle that does not answer SYSTEM_TIME counts as rebooted when its heartbeats stop for
longer than :data:`HEARTBEAT_GAP_S` and then resume. Every wait is on the vehicle's messages,
bounded by a timeout whose message says what was and was not seen.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from dataclasses import dataclass

from alphafence.errors import VehicleError
from alphafence.mavlink import ids

HEARTBEAT_GAP_S = 2.5  # ArduPilot beats at 1 Hz: this long without one, it went away
AUTOPILOT_COMPONENT = 1


class RebootError(VehicleError):
    """The vehicle would not reboot (armed, refused), or did not come back in time."""


@dataclass
class RebootReport:
    """A reboot, as the vehicle showed it.

    Attributes
    ----------
    accepted_s : float
        Seconds from sending the command to its acknowledgement.
    away_s : float or None
        Seconds from the command to the last heartbeat of the old boot (None if that was not
        seen).
    back_s : float
        Seconds from the command to the first sign of the new boot.
    boot_ms_before, boot_ms_after : int or None
        ``time_boot_ms`` before the command and in the new boot (None when the vehicle did
        not answer SYSTEM_TIME).
    """

    accepted_s: float
    away_s: float | None
    back_s: float
    boot_ms_before: int | None
    boot_ms_after: int | None


async def is_armed(vehicle, timeout: float = 5.0) -> bool:
    """Whether the vehicle says it is armed (its heartbeat's safety-armed flag).

    Raises
    ------
    RebootError
        When the vehicle does not say within ``timeout`` seconds.
    """

    async def first():
        async for armed in vehicle.telemetry.subscribe_armed():
            return bool(armed)

    try:
        return await asyncio.wait_for(first(), timeout)
    except asyncio.TimeoutError:
        raise RebootError(
            f"the vehicle did not say within {timeout:g} s whether it is armed"
        ) from None


class _Messages:
    """The autopilot's HEARTBEAT and SYSTEM_TIME messages, queued as they arrive."""

    def __init__(self, vehicle, sysid: int):
        self.vehicle = vehicle
        self.sysid = sysid
        self.queue: asyncio.Queue = asyncio.Queue()
        self.tasks = [asyncio.create_task(self._pump(n)) for n in ("HEARTBEAT", "SYSTEM_TIME")]

    async def _pump(self, name):
        async for m in self.vehicle.messages(name):
            if m.system_id == self.sysid and m.component_id == AUTOPILOT_COMPONENT:
                self.queue.put_nowait((time.monotonic(), name, m.fields))

    async def next(self, deadline: float):
        """The next message, or None at ``deadline`` (monotonic seconds)."""
        try:
            return await asyncio.wait_for(self.queue.get(), max(0.0, deadline - time.monotonic()))
        except asyncio.TimeoutError:
            return None

    def ask_time(self) -> None:
        """Ask for SYSTEM_TIME (REQUEST_MESSAGE), without waiting for the acknowledgement."""
        self.vehicle.send_command_long(ids.MAV_CMD_REQUEST_MESSAGE, ids.MAVLINK_MSG_ID_SYSTEM_TIME)

    async def close(self):
        for task in self.tasks:
            task.cancel()
        for task in self.tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task


async def _boot_ms(messages: _Messages, timeout: float) -> int | None:
    """The vehicle's ``time_boot_ms`` now (None if it does not answer SYSTEM_TIME)."""
    deadline = time.monotonic() + timeout
    next_ask = 0.0
    while True:
        now = time.monotonic()
        if now >= deadline:
            return None
        if now >= next_ask:
            messages.ask_time()
            next_ask = now + 1.0
        got = await messages.next(min(deadline, next_ask))
        if got is not None and got[1] == "SYSTEM_TIME":
            return int(got[2].get("time_boot_ms", 0))


async def reboot_vehicle(vehicle, timeout: float = 60.0) -> RebootReport:
    """Reboot the autopilot and wait until it is back (only while disarmed).

    Parameters
    ----------
    vehicle : Vehicle
        The MAVSDK connection (:func:`~alphafence.vehicle.link.open_vehicle`).
    timeout : float
        Seconds the vehicle may take to come back.

    Returns
    -------
    RebootReport

    Raises
    ------
    RebootError
        When the vehicle is armed (nothing is sent), refuses the command, does not restart,
        or does not come back within ``timeout``.
    """
    if await is_armed(vehicle):
        raise RebootError("the vehicle is armed: it is rebooted only while disarmed")
    sysid = await vehicle.system_id()
    messages = _Messages(vehicle, sysid)
    try:
        before = await _boot_ms(messages, 5.0)
        t0 = time.monotonic()
        try:
            result = await vehicle.command_long(ids.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
        except Exception as exc:
            raise RebootError(
                f"the vehicle did not acknowledge the reboot command ({exc})"
            ) from None
        if result != ids.MAV_RESULT_ACCEPTED:
            raise RebootError(
                f"the vehicle refused to reboot ({_result_name(result)}; ArduPilot refuses "
                "while armed)"
            )
        return await _wait_back(messages, t0, time.monotonic() - t0, before, timeout)
    finally:
        await messages.close()


async def _wait_back(messages, t0, accepted_s, before, timeout) -> RebootReport:
    """Wait for the new boot: a lower ``time_boot_ms``, or heartbeats after a gap."""
    deadline = t0 + timeout
    last_beat = t0
    away = None
    gap_seen = False
    while True:
        got = await messages.next(deadline)
        now = time.monotonic()
        if got is None:
            if gap_seen or now - last_beat > HEARTBEAT_GAP_S:
                raise RebootError(
                    f"the vehicle went away after the reboot command and did not come back "
                    f"within {timeout:g} s (last heartbeat {last_beat - t0:.1f} s after it)"
                )
            raise RebootError(
                f"the vehicle accepted the reboot command but did not restart within "
                f"{timeout:g} s (its heartbeats went on)"
            )
        when, name, fields = got
        if name == "HEARTBEAT":
            if when - last_beat > HEARTBEAT_GAP_S:
                gap_seen = True
                away = last_beat - t0
            last_beat = when
            if before is None:
                if gap_seen:
                    return RebootReport(accepted_s, away, when - t0, None, None)
                continue
            messages.ask_time()
        elif name == "SYSTEM_TIME" and before is not None:
            boot_ms = int(fields.get("time_boot_ms", before))
            if boot_ms < before:
                return RebootReport(accepted_s, away, when - t0, before, boot_ms)


def _result_name(result: int) -> str:
    names = {
        v: k for k, v in vars(ids).items() if k.startswith("MAV_RESULT_") and isinstance(v, int)
    }
    return names.get(result, f"MAV_RESULT {result}")
