"""Open a MAVSDK link to the autopilot, and collect the vehicle's STATUSTEXT messages (its
own words for why a transfer failed)."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque

from alphafence.errors import VehicleError


class LinkError(VehicleError):
    """The vehicle could not be reached, or went away."""


_QUIET = False


def quiet_mavsdk():
    """Keep MAVSDK's own debug and info lines off the operator's terminal (warnings and
    errors still show; the vehicle's STATUSTEXTs are collected and reported by the kit)."""
    global _QUIET
    if _QUIET:
        return
    from mavsdk.logging import LogLevel, log_subscribe

    log_subscribe(lambda level, message, file, line: level < LogLevel.WARN)
    _QUIET = True


@contextlib.asynccontextmanager
async def open_vehicle(url: str, timeout: float = 10.0, signing_key: bytes | None = None):
    """``async with open_vehicle("udpin://127.0.0.1:14550") as vehicle`` -> Vehicle.

    With ``signing_key`` (32 bytes) every message to the vehicle is signed and every message
    from it must be signed with that key, through a loopback :class:`SigningBridge`."""
    if signing_key is None:
        async with _open_mavsdk(url, url, timeout) as vehicle:
            yield vehicle
        return
    from alphafence.vehicle.bridge import BridgeError, SigningBridge

    try:
        bridge = await SigningBridge(url, signing_key).open()
    except BridgeError as exc:
        raise LinkError(str(exc)) from None
    try:
        async with _open_mavsdk(bridge.local_url, url, timeout, bridge) as vehicle:
            vehicle.bridge = bridge
            yield vehicle
    finally:
        await bridge.close()


@contextlib.asynccontextmanager
async def _open_mavsdk(url: str, shown_url: str, timeout: float, bridge=None):
    import mavsdk.asyncio as ms

    quiet_mavsdk()

    config = ms.Configuration.create_with_component_type(ms.ComponentType.GROUND_STATION)
    async with ms.Mavsdk(config) as mavsdk:
        try:
            await mavsdk.add_any_connection(url)
        except Exception as exc:  # mavsdk raises its own error types
            raise LinkError(f"{shown_url}: cannot open the connection ({exc})") from None
        try:
            system = await mavsdk.first_autopilot(timeout_s=timeout)
        except Exception:
            system = None
        if system is None:
            why = f"{shown_url}: no autopilot answered within {timeout:g} s"
            if bridge is not None and bridge.diagnosis():
                why += f" ({bridge.diagnosis()})"
            raise LinkError(why)
        vehicle = Vehicle(system, shown_url)
        await vehicle.start()
        try:
            yield vehicle
        finally:
            await vehicle.close()


class Vehicle:
    """A connected autopilot: MAVSDK's plugins for it, and the STATUSTEXTs it sent.

    Parameters
    ----------
    system : mavsdk System
        The autopilot MAVSDK discovered.
    url : str
        The connection as the operator gave it (for messages).

    Attributes
    ----------
    mission_raw, action, param, telemetry
        MAVSDK's plugins.
    texts : deque
        ``(monotonic time, text)`` of the last 50 STATUSTEXTs.
    bridge : SigningBridge or None
        The loopback signing bridge of a signed link.
    """

    def __init__(self, system, url):
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self.url = url
        self.system = system
        self.mission_raw = MissionRawAsync(system)
        self.action = ActionAsync(system)
        self.param = ParamAsync(system)
        self.telemetry = TelemetryAsync(system)
        self.texts: deque = deque(maxlen=50)  # (monotonic time, text)
        self.bridge = None  # the SigningBridge of a signed link
        self._task = None

    async def start(self):
        """Start collecting the vehicle's STATUSTEXTs."""
        self._task = asyncio.create_task(self._collect_texts())

    async def close(self):
        """Stop collecting STATUSTEXTs."""
        if self._task:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task

    async def _collect_texts(self):
        async for st in self.telemetry.subscribe_status_text():
            self.texts.append((time.monotonic(), st.text))

    async def texts_since(self, t0: float, settle: float = 0.3):
        """STATUSTEXTs received after ``t0`` (waits briefly: they trail the ACK by a few ms)."""
        await asyncio.sleep(settle)
        return [text for t, text in self.texts if t >= t0]
