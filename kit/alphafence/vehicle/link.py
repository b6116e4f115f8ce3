"""Open a link to the autopilot, whichever link this machine has, and collect the vehicle's
STATUSTEXT messages (its own words for why a transfer failed).

Two links offer the same :class:`Vehicle`:

* ``mavsdk``: MAVSDK 4's native binding (``mavsdk.asyncio``; wheels for x86-64 and arm64);
  signed links through the loopback :class:`~alphafence.vehicle.bridge.SigningBridge`;
* ``pymavlink``: :mod:`alphafence.vehicle.pymavlink_link`, pure Python on asyncio, wherever
  pymavlink installs (a Navio2's 32-bit Raspberry Pi OS included); it signs by itself.

``auto`` (the default, or ``$ALPHAFENCE_LINK``) takes :data:`PREFERRED` when it is installed,
else the other; with neither, one line says what to install.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import json
import logging
import os
import re

from alphafence.vehicle.base import LinkError, NoLinkError, Vehicle

__all__ = ["LinkError", "NoLinkError", "Vehicle", "choose_link", "open_vehicle"]

LINKS = ("auto", "pymavlink", "mavsdk")
PREFERRED = ("pymavlink", "mavsdk")  # auto's order: the leaner first (bench/link_bench.py)
INSTALL = {
    "pymavlink": "pip install pymavlink (the 'companion' extra; pure Python, any platform)",
    "mavsdk": "pip install mavsdk (MAVSDK 4: wheels for x86-64 and arm64 only, none for "
    "32-bit ARM such as a Navio2's Raspberry Pi OS)",
}


def _installed(kind: str) -> bool:
    name = "mavsdk.asyncio" if kind == "mavsdk" else "pymavlink.dialects.v20.ardupilotmega"
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):  # a parent package missing
        return False


def choose_link(link: str | None = None) -> str:
    """The link to use: ``link``, else ``$ALPHAFENCE_LINK``, else ``auto``, resolved.

    Raises
    ------
    NoLinkError
        One line naming what to install.
    """
    link = (link or os.environ.get("ALPHAFENCE_LINK") or "auto").strip().lower()
    if link not in LINKS:
        raise NoLinkError(f"unknown vehicle link {link!r} (one of {', '.join(LINKS)})")
    if link != "auto":
        if not _installed(link):
            raise NoLinkError(f"the {link} vehicle link is not installed: {INSTALL[link]}")
        return link
    for kind in PREFERRED:
        if _installed(kind):
            return kind
    raise NoLinkError(f"no vehicle link is installed: {INSTALL['pymavlink']}")


_QUIET = False
MAVSDK_LOG = logging.getLogger("alphafence.mavsdk")
_ANSI = re.compile(r"\x1b\[[0-9;?]*[ -/]*[@-~]")
# MAVSDK's levels (DEBUG 0, INFO 1, WARN 2, ERROR 3) as Python logging's
_LEVELS = (logging.DEBUG, logging.INFO, logging.WARNING, logging.ERROR)


def mavsdk_log(level: int, message: str, file=None, line=0) -> bool:
    """MAVSDK's log callback: each line goes to the ``alphafence.mavsdk`` logger, without
    terminal colour codes, at Python logging's level for MAVSDK's.

    Nothing is printed by MAVSDK itself (the callback returns True). With logging not set
    up, Python shows warnings and errors on stderr as ``mavsdk: ...`` lines.

    Examples
    --------
    >>> mavsdk_log(3, "\x1b[31mCall open failed: No such file or directory\x1b[0m")
    True
    """
    text = " ".join(_ANSI.sub("", str(message)).split())
    level = _LEVELS[min(max(int(level), 0), len(_LEVELS) - 1)]
    where = {"mavsdk_file": file, "mavsdk_line": line}
    MAVSDK_LOG.log(level, "mavsdk: %s", text, extra=where)
    return True


def quiet_mavsdk():
    """Route MAVSDK's own log lines into Python logging (:func:`mavsdk_log`), so none reaches
    the operator's terminal as raw colour codes and its debug and info lines stay off it (the
    vehicle's STATUSTEXTs are collected and reported by the kit)."""
    global _QUIET
    if _QUIET:
        return
    from mavsdk.logging import log_subscribe

    log_subscribe(mavsdk_log)
    _QUIET = True


@contextlib.asynccontextmanager
async def open_vehicle(
    url: str, timeout: float = 10.0, signing_key: bytes | None = None, link: str | None = None
):
    """``async with open_vehicle("udpin://127.0.0.1:14550") as vehicle`` -> Vehicle.

    Parameters
    ----------
    url : str
        Any form :func:`~alphafence.vehicle.endpoints.parse_endpoint` reads: a serial port
        (``/dev/ttyACM0``, ``/dev/ttyUSB0,57600``, ``COM3``), ``udpin:HOST:PORT``,
        ``udpout:HOST:PORT``, ``tcp:HOST:PORT``, ``tcpin:HOST:PORT``..., on either link.
    timeout : float
        Seconds to wait for the autopilot's heartbeat.
    signing_key : bytes, optional
        32 bytes: every message to the vehicle is signed and every message from it must be.
    link : str, optional
        ``auto``, ``pymavlink`` or ``mavsdk`` (see :func:`choose_link`).
    """
    from alphafence.vehicle.endpoints import parse_endpoint

    endpoint = parse_endpoint(url)
    if choose_link(link) == "pymavlink":
        from alphafence.vehicle.pymavlink_link import PymavlinkVehicle

        vehicle = await PymavlinkVehicle(url, signing_key).connect(timeout)
        try:
            yield vehicle
        finally:
            await vehicle.close()
        return
    if signing_key is None and endpoint.mavsdk_url is not None:
        if endpoint.kind == "serial" and os.name == "posix":
            _check_serial(endpoint)
        async with _open_mavsdk(endpoint.mavsdk_url, url, timeout) as vehicle:
            yield vehicle
        return
    # MAVSDK cannot sign (nor broadcast): the kit's bridge carries the link, serial included
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


def _check_serial(endpoint) -> None:
    """The kit's one-line error for a serial port MAVSDK would fail to open, before it tries
    (it says only CONNECTION_ERROR)."""
    from alphafence.vehicle.transports import serial_error

    try:
        fd = os.open(endpoint.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise LinkError(str(serial_error(endpoint.device, endpoint.baud, exc))) from None
    os.close(fd)


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
        vehicle = MavsdkVehicle(system, shown_url)
        await vehicle.identify(timeout)
        await vehicle.start()
        try:
            yield vehicle
        finally:
            await vehicle.close()


class MavsdkVehicle(Vehicle):
    """The MAVSDK link: MAVSDK's plugins, and the kit's methods built on them.

    Parameters
    ----------
    system : mavsdk System
        The autopilot MAVSDK discovered.
    url : str
        The connection as the operator gave it.
    """

    kind = "mavsdk"

    def __init__(self, system, url):
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        super().__init__(url)
        self.system = system
        self.mission_raw = MissionRawAsync(system)
        self.action = ActionAsync(system)
        self.param = ParamAsync(system)
        self.telemetry = TelemetryAsync(system)
        self.direct = MavlinkDirectAsync(system)

    async def messages(self, name: str):
        """Every ``name`` message on the link, from any system, as a
        :class:`~alphafence.vehicle.values.Message` (fields that are not JSON: skipped)."""
        from alphafence.vehicle.values import Message

        async for m in self.direct.subscribe_message(name):
            try:
                fields = json.loads(m.fields_json)
            except ValueError:
                continue
            if isinstance(fields, dict):
                yield Message(name, m.system_id, m.component_id, fields)

    async def identify(self, timeout: float) -> None:
        """Read which autopilot this is from its HEARTBEAT (``autopilot``); ArduPilot when
        none comes within ``timeout``."""
        from alphafence.mavlink.autopilots import autopilot_of

        async def first():
            async for m in self.messages("HEARTBEAT"):
                kind = autopilot_of(m.fields.get("autopilot", -1))
                if kind is not None:
                    return kind

        with contextlib.suppress(asyncio.TimeoutError):
            self.autopilot = await asyncio.wait_for(first(), timeout) or self.autopilot

    def _command(self, command, params, target_component):
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        from alphafence.mavlink.commands import command_long_json

        sysid = self._sysid
        fields = command_long_json(sysid, target_component, command, *params)
        return MavlinkMessage("COMMAND_LONG", 0, 0, sysid, target_component, fields)

    async def command_long(self, command: int, *params, target_component=1) -> int:
        """Send a COMMAND_LONG and return its COMMAND_ACK's ``result``."""
        self._sysid = await self.system_id()
        ack = await self.direct.send_command(self._command(command, params, target_component))
        return int(json.loads(ack.fields_json or "{}").get("result", -1))

    def send_command_long(self, command: int, *params, target_component=1) -> None:
        """Send a COMMAND_LONG without waiting for its answer (after a :meth:`system_id`)."""
        task = asyncio.ensure_future(
            self.direct.send_message(self._command(command, params, target_component))
        )
        task.add_done_callback(lambda t: t.cancelled() or t.exception())

    _sysid = 1

    async def system_id(self) -> int:
        """The vehicle's MAVLink system id (ArduPilot's default, 1, if MAVSDK cannot say)."""
        try:
            self._sysid = int(await self.system.get_system_id())
        except Exception:
            pass
        return self._sysid

    async def send_status_text(self, severity: int, text: str) -> None:
        """A STATUSTEXT to the ground station (``MAV_SEVERITY``: CRITICAL or WARNING)."""
        from mavsdk.asyncio.plugins.server_utility import ServerUtilityAsync
        from mavsdk.plugins.server_utility import StatusTextType

        from alphafence.mavlink import ids

        kind = (
            StatusTextType.CRITICAL
            if severity <= ids.MAV_SEVERITY_CRITICAL
            else (StatusTextType.WARNING)
        )
        await ServerUtilityAsync(self.system).send_status_text(kind, text)

    async def upload_geofence(self, items) -> None:
        """Upload ``items`` (FenceItems) as the fence; TransferFailed on failure."""
        from mavsdk.plugins.mission_raw import MissionItem, MissionRawError

        from alphafence.geo.coords import to_e7
        from alphafence.mavlink import ids
        from alphafence.vehicle.values import TransferFailed

        raw = [
            MissionItem(i, ids.MAV_FRAME_GLOBAL, it.command, 0, 1, float(it.param1), 0.0, 0.0,
                        0.0, to_e7(it.lat), to_e7(it.lon), 0.0, ids.MAV_MISSION_TYPE_FENCE)
            for i, it in enumerate(items)
        ]  # fmt: skip
        try:
            await self.mission_raw.upload_geofence(raw)
        except MissionRawError as exc:
            raise TransferFailed(_result(exc)) from None

    async def download_geofence(self, max_items: int | None = None) -> list:
        """The fence's raw items ([] when there is none); TransferFailed on failure."""
        from mavsdk.plugins.mission_raw import MissionRawError

        from alphafence.vehicle.values import TransferFailed

        try:
            return list(await self.mission_raw.download_geofence())
        except MissionRawError as exc:
            if _result(exc) == "NO_MISSION_AVAILABLE":
                return []
            raise TransferFailed(_result(exc)) from None

    async def is_connected(self) -> bool:
        """Whether MAVSDK still hears the vehicle."""
        return bool(await self.system.is_connected())

    def link_diagnosis(self) -> str:
        """Why the vehicle may be silent ('' when nothing points to a reason)."""
        return self.bridge.diagnosis() if self.bridge is not None else ""

    def link_stats(self):
        """The signing bridge's counts (:class:`~alphafence.vehicle.bridge.LinkStats`), or
        None without a bridge."""
        return self.bridge.link.stats if self.bridge is not None else None


def _result(exc) -> str:
    result = getattr(exc, "result", None)
    return str(getattr(result, "name", result))
