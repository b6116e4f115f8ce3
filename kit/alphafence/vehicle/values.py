"""What a vehicle link delivers, whichever link it is: telemetry values, raw mission items,
MAVLink messages, flight-mode names, and the one error a transfer raises.

The monitor, the fence transfer and the parameter code read these attributes and nothing
else, so the native MAVSDK link (whose own values have the same attribute names) and the
pymavlink link (:mod:`alphafence.vehicle.pymavlink_link`, which builds these) run the same code.
Flight modes are named as the autopilot names them (:func:`mode_name`). ArduPilot's as ArduPilot
names them (``GUIDED``, ``AUTO``, ``BRAKE``, ``LOITER``, ``RTL``, ...), from the HEARTBEAT's
``custom_mode`` by pymavlink's mode maps for the vehicle's type; MAVSDK's names for them
(``OFFBOARD``, ``MISSION``, ``HOLD``, from MAVSDK's link and traces recorded through it) are
read as the ArduPilot mode they stand for (:func:`ardupilot_mode`). PX4's by the names MAVSDK,
PX4's own SDK, gives them (``HOLD``, ``MISSION``, ``RETURN_TO_LAUNCH``, ``POSCTL``, ...), on
either link (:func:`px4_flight_mode`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from alphafence.mavlink import ids
from alphafence.mavlink.autopilots import ARDUPILOT, PX4


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
    """A flight mode by ArduPilot's name (``name``, e.g. ``GUIDED``) and number
    (``custom_mode``)."""

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


# MAVSDK's FlightMode names (its link, traces recorded through it) -> the ArduPilot mode each
# stands for on a copter, plane and rover; HOLD is the mode the kit's hold commands (BRAKE on
# a copter, LOITER on a plane, HOLD on a rover). ArduPilot's own names are read as they are.
MAVSDK_NAMES = {
    "OFFBOARD": ("GUIDED", "GUIDED", "GUIDED"),
    "MISSION": ("AUTO", "AUTO", "AUTO"),
    "HOLD": ("BRAKE", "LOITER", "HOLD"),
    "RETURN_TO_LAUNCH": ("RTL", "RTL", "RTL"),
    "LAND": ("LAND", "QLAND", "HOLD"),
    "ALTCTL": ("ALT_HOLD", "FBWB", "MANUAL"),
    "POSCTL": ("POSHOLD", "CRUISE", "MANUAL"),
    "STABILIZED": ("STABILIZE", "STABILIZE", "MANUAL"),
    "TAKEOFF": ("GUIDED", "TAKEOFF", "GUIDED"),
}


@dataclass(frozen=True)
class ModeSet:
    """One vehicle class's modes: names by number, and the numbers the kit commands."""

    kind: str  # "copter", "plane", "rover": the column of MAVSDK_NAMES
    hold: int
    rtl: int
    land: int | None
    guided: int
    auto: int

    @property
    def names(self) -> dict:
        """ArduPilot's mode names by ``custom_mode``: pymavlink's mode map of the class."""
        from pymavlink import mavutil

        return {
            "copter": mavutil.mode_mapping_acm,
            "plane": mavutil.mode_mapping_apm,
            "rover": mavutil.mode_mapping_rover,
        }[self.kind]


COPTER = ModeSet(
    "copter",
    ids.COPTER_MODE_BRAKE,
    ids.COPTER_MODE_RTL,
    ids.COPTER_MODE_LAND,
    ids.COPTER_MODE_GUIDED,
    ids.COPTER_MODE_AUTO,
)
PLANE = ModeSet(
    "plane",
    ids.PLANE_MODE_LOITER,
    ids.PLANE_MODE_RTL,
    ids.PLANE_MODE_QLAND,
    ids.PLANE_MODE_GUIDED,
    ids.PLANE_MODE_AUTO,
)
ROVER = ModeSet(
    "rover",
    ids.ROVER_MODE_HOLD,
    ids.ROVER_MODE_RTL,
    None,
    ids.ROVER_MODE_GUIDED,
    ids.ROVER_MODE_AUTO,
)


def ardupilot_mode(name: str | None, mav_type: int = ids.MAV_TYPE_QUADROTOR) -> str | None:
    """A flight mode's ArduPilot name: MAVSDK's names (:data:`MAVSDK_NAMES`) as the mode they
    stand for on a vehicle of HEARTBEAT ``type`` ``mav_type``, any other name as it is.

    Examples
    --------
    >>> ardupilot_mode("OFFBOARD"), ardupilot_mode("HOLD", 1), ardupilot_mode("LOITER")
    ('GUIDED', 'LOITER', 'LOITER')
    """
    if name not in MAVSDK_NAMES:
        return name
    column = ("copter", "plane", "rover").index(mode_set(mav_type).kind)
    return MAVSDK_NAMES[name][column]


def custom_mode_of(name: str | None, mav_type: int = ids.MAV_TYPE_QUADROTOR) -> int | None:
    """ArduPilot's ``custom_mode`` number of a mode name (either naming), or None.

    Examples
    --------
    >>> custom_mode_of("GUIDED"), custom_mode_of("HOLD"), custom_mode_of("RTL", 10)
    (4, 17, 11)
    """
    names = {v: k for k, v in mode_set(mav_type).names.items()}
    return names.get(ardupilot_mode(name, mav_type))


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
    ('GUIDED', 'BRAKE', 'UNKNOWN')
    """
    return FlightMode(mode_set(mav_type).names.get(custom_mode, "UNKNOWN"), int(custom_mode))


# PX4's modes (px4_custom_mode.h): its name -> main mode, sub mode (carried in a HEARTBEAT's
# custom_mode as bits 16-23 and 24-31) and the name MAVSDK's FlightMode gives it.
PX4_MODES = {
    "MANUAL": (1, 0, "MANUAL"),
    "ALTCTL": (2, 0, "ALTCTL"),
    "POSCTL": (3, 0, "POSCTL"),
    "AUTO.TAKEOFF": (4, 2, "TAKEOFF"),
    "AUTO.LOITER": (4, 3, "HOLD"),
    "AUTO.MISSION": (4, 4, "MISSION"),
    "AUTO.RTL": (4, 5, "RETURN_TO_LAUNCH"),
    "AUTO.LAND": (4, 6, "LAND"),
    "ACRO": (5, 0, "ACRO"),
    "OFFBOARD": (6, 0, "OFFBOARD"),
    "STABILIZED": (7, 0, "STABILIZED"),
}
_PX4_BY_NUMBER = {(main, sub): name for name, (main, sub, _) in PX4_MODES.items()}


def px4_custom_mode(name: str) -> int:
    """A PX4 mode's ``custom_mode`` (``AUTO.LOITER``: main mode 4, sub mode 3).

    Examples
    --------
    >>> hex(px4_custom_mode("AUTO.LOITER")), hex(px4_custom_mode("POSCTL"))
    ('0x3040000', '0x30000')
    """
    main, sub, _ = PX4_MODES[name]
    return main << 16 | sub << 24


def px4_flight_mode(custom_mode: int) -> FlightMode:
    """A PX4 HEARTBEAT's mode as a :class:`FlightMode`, named as MAVSDK names it (so the
    pymavlink link names PX4's modes as MAVSDK's does: Hold is ``HOLD``, Mission
    ``MISSION``, Return ``RETURN_TO_LAUNCH``, Position ``POSCTL``).

    Examples
    --------
    >>> px4_flight_mode(px4_custom_mode("AUTO.LOITER")).name, px4_flight_mode(0x40000).name
    ('HOLD', 'UNKNOWN')
    """
    main, sub = (int(custom_mode) >> 16) & 0xFF, (int(custom_mode) >> 24) & 0xFF
    name = _PX4_BY_NUMBER.get((main, sub)) or _PX4_BY_NUMBER.get((main, 0))
    if name is None or (main == 4 and sub == 0):
        return FlightMode("UNKNOWN", int(custom_mode))
    return FlightMode(PX4_MODES[name][2], int(custom_mode))


# the mode a goto flies in (ArduPilot's GUIDED; PX4's reposition holds at the target) and the
# mode that flies the mission, by autopilot (``Vehicle.autopilot``), as :func:`mode_name` names them
GOTO_MODE = {ARDUPILOT: "GUIDED", PX4: "HOLD"}
MISSION_MODE = {ARDUPILOT: "AUTO", PX4: "MISSION"}


def mode_name(name: str | None, autopilot: str = ARDUPILOT) -> str | None:
    """A flight mode as the kit names it on a vehicle of ``autopilot``: ArduPilot's name on
    ArduPilot (MAVSDK's names read by :func:`ardupilot_mode`, as a copter's), MAVSDK's on PX4.

    Examples
    --------
    >>> mode_name("HOLD"), mode_name("HOLD", "px4"), mode_name("MISSION", "px4")
    ('BRAKE', 'HOLD', 'MISSION')
    """
    return name if autopilot == PX4 else ardupilot_mode(name)
