"""What a vehicle link delivers, whichever link it is: telemetry values, raw mission items,
MAVLink messages, flight-mode names, and the one error a transfer raises.

The monitor, the fence transfer and the parameter code read these attributes and nothing
else, so the native MAVSDK link (whose own values have the same attribute names) and the
pymavlink link (:mod:`alphafence.vehicle.pymavlink_link`, which builds these) run the same code.
Flight modes are named as MAVSDK names them (``OFFBOARD`` for ArduPilot's GUIDED, ``MISSION``
for AUTO, ``HOLD`` for BRAKE and LOITER), so the engine's rules need no second table.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from alphafence.mavlink import ids


@dataclass(frozen=True, slots=True)
class Position:
    """GLOBAL_POSITION_INT's position: degrees, and metres above mean sea level and home."""

    latitude_deg: float
    longitude_deg: float
    absolute_altitude_m: float
    relative_altitude_m: float


@dataclass(frozen=True, slots=True)
class VelocityNed:
    """GLOBAL_POSITION_INT's velocity in m/s, north, east and down."""

    north_m_s: float
    east_m_s: float
    down_m_s: float


@dataclass(frozen=True, slots=True)
class FlightMode:
    """A flight mode by MAVSDK's name (``name``) and ArduPilot's number (``custom_mode``)."""

    name: str
    custom_mode: int


@dataclass(frozen=True, slots=True)
class GpsInfo:
    """GPS_RAW_INT's satellites in view and fix type (``GPS_FIX_TYPE``)."""

    num_satellites: int
    fix_type: int


@dataclass(frozen=True, slots=True)
class StatusText:
    """A STATUSTEXT: severity (``MAV_SEVERITY``) and text."""

    type: int
    text: str


@dataclass(frozen=True, slots=True)
class MissionProgress:
    """AUTO's current mission item and the number of items (MISSION_CURRENT)."""

    current: int
    total: int


@dataclass(frozen=True, slots=True)
class RawItem:
    """A MISSION_ITEM_INT as read from the vehicle (MAVSDK's ``mission_raw`` field names)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int


@dataclass(frozen=True, slots=True)
class Message:
    """A MAVLink message by name: who sent it and its fields (a dict of plain values)."""

    name: str
    system_id: int
    component_id: int
    fields: dict


def fields_of(value) -> dict:
    """A message's fields: a dict as it is, JSON text (MAVSDK's ``fields_json``) parsed.

    Raises ValueError when JSON text is not an object.

    Examples
    --------
    >>> fields_of('{"lat": 1}'), fields_of({"lat": 1})
    ({'lat': 1}, {'lat': 1})
    """
    if isinstance(value, dict):
        return value
    fields = json.loads(value)
    if not isinstance(fields, dict):
        raise ValueError("the fields are not an object")
    return fields


class TransferFailed(Exception):
    """A mission-protocol transfer failed; ``result`` names why, in MAVSDK's
    ``MissionRawResult`` names (``TIMEOUT``, ``DENIED``, ``PROTOCOL_ERROR``, ...), whichever
    link it was, so :mod:`alphafence.vehicle.fence_transfer` words them once."""

    def __init__(self, result: str, detail: str = ""):
        self.result = result
        self.detail = detail
        super().__init__(f"{result}{': ' + detail if detail else ''}")


MISSION_RESULTS = {
    ids.MAV_MISSION_ERROR: "PROTOCOL_ERROR",
    ids.MAV_MISSION_UNSUPPORTED_FRAME: "UNSUPPORTED",
    ids.MAV_MISSION_UNSUPPORTED: "UNSUPPORTED",
    ids.MAV_MISSION_NO_SPACE: "TOO_MANY_MISSION_ITEMS",
    ids.MAV_MISSION_INVALID: "INVALID_ARGUMENT",
    ids.MAV_MISSION_INVALID_SEQUENCE: "INVALID_SEQUENCE",
    ids.MAV_MISSION_DENIED: "DENIED",
    ids.MAV_MISSION_OPERATION_CANCELLED: "TRANSFER_CANCELLED",
}
"""MISSION_ACK results -> MAVSDK's ``MissionRawResult`` names (as MAVSDK maps them; the
INVALID_PARAM results are INVALID_ARGUMENT too)."""


def mission_result_name(result: int) -> str:
    """The ``MissionRawResult`` name of a MISSION_ACK ``result``.

    Examples
    --------
    >>> mission_result_name(4), mission_result_name(8), mission_result_name(99)
    ('TOO_MANY_MISSION_ITEMS', 'INVALID_ARGUMENT', 'PROTOCOL_ERROR')
    """
    if ids.MAV_MISSION_INVALID_PARAM1 <= result <= ids.MAV_MISSION_INVALID_PARAM7:
        return "INVALID_ARGUMENT"
    return MISSION_RESULTS.get(result, "PROTOCOL_ERROR")


# ArduPilot's modes by vehicle class: custom_mode -> MAVSDK's FlightMode name
COPTER_MODES = {
    ids.COPTER_MODE_STABILIZE: "STABILIZED",
    ids.COPTER_MODE_ACRO: "ACRO",
    ids.COPTER_MODE_ALT_HOLD: "ALTCTL",
    ids.COPTER_MODE_AUTO: "MISSION",
    ids.COPTER_MODE_GUIDED: "OFFBOARD",
    ids.COPTER_MODE_LOITER: "HOLD",
    ids.COPTER_MODE_RTL: "RETURN_TO_LAUNCH",
    ids.COPTER_MODE_LAND: "LAND",
    ids.COPTER_MODE_POSHOLD: "POSCTL",
    ids.COPTER_MODE_BRAKE: "HOLD",
    ids.COPTER_MODE_SMART_RTL: "RETURN_TO_LAUNCH",
}
PLANE_MODES = {
    ids.PLANE_MODE_MANUAL: "MANUAL",
    ids.PLANE_MODE_AUTO: "MISSION",
    ids.PLANE_MODE_RTL: "RETURN_TO_LAUNCH",
    ids.PLANE_MODE_LOITER: "HOLD",
    ids.PLANE_MODE_GUIDED: "OFFBOARD",
    ids.PLANE_MODE_QLAND: "LAND",
}
ROVER_MODES = {
    ids.ROVER_MODE_MANUAL: "MANUAL",
    ids.ROVER_MODE_HOLD: "HOLD",
    ids.ROVER_MODE_AUTO: "MISSION",
    ids.ROVER_MODE_RTL: "RETURN_TO_LAUNCH",
    ids.ROVER_MODE_SMART_RTL: "RETURN_TO_LAUNCH",
    ids.ROVER_MODE_GUIDED: "OFFBOARD",
}


@dataclass(frozen=True)
class ModeSet:
    """One vehicle class's modes: names by number, and the numbers the kit commands."""

    names: dict
    hold: int
    rtl: int
    land: int | None
    guided: int
    auto: int


COPTER = ModeSet(
    COPTER_MODES,
    ids.COPTER_MODE_BRAKE,
    ids.COPTER_MODE_RTL,
    ids.COPTER_MODE_LAND,
    ids.COPTER_MODE_GUIDED,
    ids.COPTER_MODE_AUTO,
)
PLANE = ModeSet(
    PLANE_MODES,
    ids.PLANE_MODE_LOITER,
    ids.PLANE_MODE_RTL,
    ids.PLANE_MODE_QLAND,
    ids.PLANE_MODE_GUIDED,
    ids.PLANE_MODE_AUTO,
)
ROVER = ModeSet(
    ROVER_MODES,
    ids.ROVER_MODE_HOLD,
    ids.ROVER_MODE_RTL,
    None,
    ids.ROVER_MODE_GUIDED,
    ids.ROVER_MODE_AUTO,
)


def mode_set(mav_type: int) -> ModeSet:
    """The modes of a vehicle whose HEARTBEAT says ``type`` (a copter unless it is a plane
    or a rover/boat)."""
    if mav_type == ids.MAV_TYPE_FIXED_WING:
        return PLANE
    if mav_type in (ids.MAV_TYPE_GROUND_ROVER, ids.MAV_TYPE_SURFACE_BOAT):
        return ROVER
    return COPTER


def flight_mode(mav_type: int, custom_mode: int) -> FlightMode:
    """A HEARTBEAT's mode as a :class:`FlightMode`.

    Examples
    --------
    >>> flight_mode(2, 4).name, flight_mode(2, 17).name, flight_mode(2, 99).name
    ('OFFBOARD', 'HOLD', 'UNKNOWN')
    """
    return FlightMode(mode_set(mav_type).names.get(custom_mode, "UNKNOWN"), int(custom_mode))
