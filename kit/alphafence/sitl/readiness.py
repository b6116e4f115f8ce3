"""When a SITL vehicle is ready: what it must have said, and the listener that hears it.

Readiness is the vehicle's own word, from its MAVLink messages: an autopilot heartbeat, a 3D
GPS fix, an EKF absolute horizontal position, a GLOBAL_POSITION_INT fix and a home position
(:class:`ReadyState`). :class:`ReadinessListener` listens on the instance's UDP port with the
kit's pymavlink-over-UDP endpoint (:class:`~alphafence.mavlink.udp.MavlinkDatagrams`: no
thread, no blocking call), asks the vehicle for the messages it has not sent yet, and closes
the port when done, so that MAVSDK or pymavlink can bind it next.
"""

from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass, field

from alphafence.geo.coords import from_e7
from alphafence.mavlink import ids
from alphafence.mavlink.commands import command_long_fields
from alphafence.mavlink.udp import MavlinkDatagrams

# the messages readiness asks for while it waits (5 Hz), by name as pymavlink types them
WATCHED = {
    "GPS_RAW_INT": ids.MAVLINK_MSG_ID_GPS_RAW_INT,
    "GLOBAL_POSITION_INT": ids.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    "EKF_STATUS_REPORT": ids.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
}
WATCH_INTERVAL_US = 200_000
GCS_SOURCE = (255, 190)  # the listener's system and component (a ground station)


@dataclass
class ReadyState:
    """What readiness watches, from the vehicle's own MAVLink messages.

    Attributes
    ----------
    system : tuple of int or None
        ``(sysid, compid)`` of the autopilot, from its heartbeat.
    gps_fix : int
        GPS_RAW_INT's fix type (3: 3D).
    ekf_flags : int or None
        EKF_STATUS_REPORT's flags.
    position, home : tuple of float or None
        ``(lat, lon, alt)``: degrees and metres above mean sea level.
    status_texts : deque
        The vehicle's last eight STATUSTEXTs, for a message when it does not get ready.
    """

    system: tuple[int, int] | None = None
    gps_fix: int = 0
    ekf_flags: int | None = None
    position: tuple[float, float, float] | None = None
    home: tuple[float, float, float] | None = None
    status_texts: deque = field(default_factory=lambda: deque(maxlen=8))

    @property
    def ekf_position_ok(self) -> bool:
        """ArduPilot's own test while disarmed: an absolute (or predicted absolute) horizontal
        position, and not in constant-position mode ("Need Position Estimate" otherwise)."""
        f = self.ekf_flags
        if f is None:
            return False
        return bool(f & (ids.EKF_POS_HORIZ_ABS | ids.EKF_PRED_POS_HORIZ_ABS)) and not (
            f & ids.EKF_CONST_POS_MODE
        )

    @property
    def ready(self) -> bool:
        """Every condition holds: heartbeat, 3D fix, EKF position, position and home."""
        return (
            self.system is not None
            and self.gps_fix >= ids.GPS_FIX_TYPE_3D_FIX
            and self.ekf_position_ok
            and self.position is not None
            and self.home is not None
        )

    def describe(self) -> str:
        """Each condition in words, and the vehicle's last messages (for a timeout)."""
        parts = [
            "heartbeat seen" if self.system else "no heartbeat",
            f"GPS fix type {self.gps_fix}",
            "no EKF status"
            if self.ekf_flags is None
            else f"EKF flags {self.ekf_flags:#x}"
            + ("" if self.ekf_position_ok else " (no absolute horizontal position yet)"),
            "position known" if self.position else "no position",
            "home set" if self.home else "home not set",
        ]
        text = ", ".join(parts)
        if self.status_texts:
            text += "; last messages: " + " | ".join(self.status_texts)
        return text

    def update(self, msg) -> None:
        """Take what a pymavlink message says about readiness (other messages: nothing)."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type != ids.MAV_TYPE_GCS and msg.autopilot != ids.MAV_AUTOPILOT_INVALID:
                self.system = (msg.get_srcSystem(), msg.get_srcComponent())
        elif kind == "GPS_RAW_INT":
            self.gps_fix = msg.fix_type
        elif kind == "EKF_STATUS_REPORT":
            self.ekf_flags = msg.flags
        elif kind == "GLOBAL_POSITION_INT":
            if msg.lat or msg.lon:
                self.position = (from_e7(msg.lat), from_e7(msg.lon), msg.alt * 1e-3)
        elif kind == "HOME_POSITION":
            self.home = (from_e7(msg.latitude), from_e7(msg.longitude), msg.altitude * 1e-3)
        elif kind == "STATUSTEXT":
            self.status_texts.append(msg.text)


class ReadinessListener:
    """Hears a SITL vehicle on its UDP port and fills a :class:`ReadyState`.

    Parameters
    ----------
    state : ReadyState
        Updated with every message heard.

    Attributes
    ----------
    seen : set of str
        The types of the messages heard so far.
    changed : asyncio.Event
        Set whenever a message was heard (the waiter clears it).
    """

    def __init__(self, state: ReadyState):
        from pymavlink.dialects.v20 import ardupilotmega

        self.state = state
        self.seen: set[str] = set()
        self.changed = asyncio.Event()
        codec = ardupilotmega.MAVLink(None, srcSystem=GCS_SOURCE[0], srcComponent=GCS_SOURCE[1])
        self.wire = MavlinkDatagrams(codec, self._heard)

    async def open(self, host: str, port: int) -> ReadinessListener:
        """Listen on ``host:port``. Raises OSError when it cannot be bound."""
        await self.wire.open(local_addr=(host, port))
        return self

    async def close(self) -> None:
        """Stop listening, and wait until the port is free again."""
        await self.wire.close()

    def _heard(self, msg, addr) -> None:
        self.seen.add(msg.get_type())
        self.state.update(msg)
        self.changed.set()

    def command(self, command: int, *params: float) -> None:
        """Send a COMMAND_LONG to the autopilot (nothing until its heartbeat was heard)."""
        if self.wire.peer is None or self.state.system is None:
            return
        fields = command_long_fields(*self.state.system, command, *params)
        self.wire.send(self.wire.mav.command_long_encode(**fields))

    def ask(self) -> None:
        """Ask for the watched messages not seen yet (5 Hz), and for the home position."""
        for name, msgid in WATCHED.items():
            if name not in self.seen:
                self.command(ids.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, WATCH_INTERVAL_US)
        if self.state.home is None:
            self.command(ids.MAV_CMD_REQUEST_MESSAGE, ids.MAVLINK_MSG_ID_HOME_POSITION)

    def reset(self) -> None:
        """The watched messages back to the vehicle's default rates."""
        for msgid in WATCHED.values():
            self.command(ids.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, 0)
