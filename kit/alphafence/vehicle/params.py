"""Fence parameter profiles (AC_Fence), set and read back."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from alphafence.errors import VehicleError
from alphafence.vehicle.px4 import INTEGER as PX4_INTEGER
from alphafence.vehicle.px4 import PRESETS as PX4_PRESETS
from alphafence.vehicle.px4 import describe as px4_describe

# The presets, per vehicle, as ArduPilot's AC_Fence documents its parameters
# (libraries/AC_Fence/AC_Fence.cpp): FENCE_ENABLE 1 enabled; FENCE_TYPE bits 0 max altitude
# (Copter, Plane), 1 circle around home, 2 inclusion/exclusion polygons and circles, 3 min
# altitude; FENCE_ACTION per vehicle (:data:`ACTIONS`). Rover has no altitude fence (no
# FENCE_ALT_MAX, FENCE_TYPE bit 0 is not one of its bits).
ACTIONS = {
    "copter": {
        0: "Report Only",
        1: "RTL or Land",
        2: "Always Land",
        3: "SmartRTL or RTL or Land",
        4: "Brake or Land",
        5: "SmartRTL or Land",
    },
    "plane": {
        0: "Report Only",
        1: "RTL",
        6: "Guided",
        7: "GuidedThrottlePass",
        8: "AUTOLAND if possible else RTL",
    },
    "rover": {
        0: "Report Only",
        1: "RTL or Hold",
        2: "Hold",
        3: "SmartRTL or RTL or Hold",
        4: "SmartRTL or Hold",
        5: "Terminate",
        6: "Loiter or Hold",
    },
}
"""FENCE_ACTION's values by vehicle, as AC_Fence.cpp's ``@Values{Copter}`` (``{Plane}``,
``{Rover}``) name them."""
_ACTION_OF = {
    "copter": {"rtl": 1, "land": 2, "smartrtl": 3, "brake": 4, "report": 0},
    "plane": {"rtl": 1, "guided": 6, "report": 0},
    "rover": {"rtl": 1, "hold": 2, "smartrtl": 3, "report": 0},
}
VEHICLE = {
    f"{vehicle}-{what}": vehicle for vehicle, actions in _ACTION_OF.items() for what in actions
}
"""The vehicle each preset is for (``copter``, ``plane``, ``rover``)."""


def _preset(vehicle: str, action: int) -> dict:
    values = {"FENCE_ENABLE": 1, "FENCE_TYPE": 4 if vehicle == "rover" else 5}
    values.update(FENCE_ACTION=action, FENCE_MARGIN=2.0)
    if vehicle != "rover":
        values["FENCE_ALT_MAX"] = 120.0
    return values


PROFILES = {
    f"{vehicle}-{what}": _preset(vehicle, action)
    for vehicle, actions in _ACTION_OF.items()
    for what, action in actions.items()
}
PROFILES.update(PX4_PRESETS)
VEHICLE.update(dict.fromkeys(PX4_PRESETS, "px4"))
"""The presets: name -> the parameters each sets, in the order set (``upload --params``);
ArduPilot's by vehicle, then PX4's (:mod:`alphafence.vehicle.px4`)."""
INTEGER = {"FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "FENCE_OPTIONS", "BRD_SD_FENCE",
           *PX4_INTEGER}  # fmt: skip

# How far a Copter goes past the fence it holds when ArduPilot alone acts on the breach
# (FENCE_ACTION 4, copter-brake, or 1, copter-rtl), flown straight at the fence at each ground
# speed (m/s): the deepest position past it, metres, measured on Copter SITL (+ quad, no wind,
# exact positions; the breach is declared at the fence itself, FENCE_MARGIN 2 does not move
# it). BRAKE: 9.3-9.4 m at 5 m/s, 21.0-21.3 m at 10 m/s; RTL: 6.6 m and 21.2-21.8 m. Each is
# the deepest measured rounded up to leave at least half a metre (5 m/s) and a metre (10 m/s)
# for where the breach is caught (ArduPilot checks the fence 25 times a second).
STOP_OVERSHOOT_M = {5.0: 10.0, 10.0: 23.0}
# The margin a keep-out fence needs around its zone at each speed when the vehicle's own fence
# is all that stops it: at least 2 m beyond the overshoot, in steps of 5 m. What is left of it
# (about 3.5 m at 10 m/s) is all there is for the vehicle's position error and wind. The default
# rules' keep-out margins are at least the 10 m/s one (WPNAV_SPEED's default); flying faster
# needs wider margins (``--margin``, or a rules file).
MARGIN_FOR_SPEED_M = {5.0: 15.0, 10.0: 25.0}


class ParamError(VehicleError):
    """A fence parameter could not be set or read, or reads back differently."""


def describe(name: str) -> str:
    """A preset's parameters and what its FENCE_ACTION does, on one line.

    Examples
    --------
    >>> describe("rover-hold")
    'FENCE_ENABLE=1 FENCE_TYPE=4 FENCE_ACTION=2 (Hold) FENCE_MARGIN=2'
    """
    if VEHICLE[name] == "px4":
        return px4_describe(name)
    values, actions = PROFILES[name], ACTIONS[VEHICLE[name]]
    return " ".join(
        f"{k}={v:g}" + (f" ({actions[v]})" if k == "FENCE_ACTION" else "")
        for k, v in values.items()
    )


def vehicle_kind(mav_type: int) -> str | None:
    """``"copter"``, ``"plane"`` or ``"rover"`` for a HEARTBEAT ``type``, as pymavlink's
    mode maps class it (a boat is a rover, a VTOL a plane); None for another vehicle.

    Examples
    --------
    >>> vehicle_kind(2), vehicle_kind(1), vehicle_kind(11), vehicle_kind(12)
    ('copter', 'plane', 'rover', None)
    """
    from pymavlink import mavutil

    mapping = mavutil.mode_mapping_bynumber(mav_type)
    for kind, modes in (
        ("copter", mavutil.mode_mapping_acm),
        ("plane", mavutil.mode_mapping_apm),
        ("rover", mavutil.mode_mapping_rover),
    ):
        if mapping is modes:
            return kind
    # older pymavlink (the floor) maps no modes for VTOL types: ArduPlane's quadplanes report them
    from pymavlink.dialects.v20 import ardupilotmega as mav

    entry = mav.enums["MAV_TYPE"].get(mav_type)
    return "plane" if entry is not None and entry.name.startswith("MAV_TYPE_VTOL") else None


async def heartbeat_type(vehicle, timeout: float = 5.0) -> int:
    """The autopilot's HEARTBEAT ``type``: the pymavlink link's own record of it, else the
    first HEARTBEAT of the vehicle's system (either link).

    Raises
    ------
    ParamError
        No HEARTBEAT from the autopilot within ``timeout`` seconds.
    """
    import asyncio

    from alphafence.mavlink import ids

    if getattr(vehicle, "mav_type", None) is not None:
        return int(vehicle.mav_type)
    sysid = await vehicle.system_id()

    async def first():
        async for m in vehicle.messages("HEARTBEAT"):
            if m.system_id == sysid and m.fields.get("autopilot") != ids.MAV_AUTOPILOT_INVALID:
                return int(m.fields["type"])

    try:
        return await asyncio.wait_for(first(), timeout)
    except asyncio.TimeoutError:
        raise ParamError(
            f"no HEARTBEAT from the vehicle in {timeout:g} s: its type is unknown"
        ) from None


async def check_preset(vehicle, name: str) -> None:
    """Refuse the preset ``name`` for a vehicle of another type, before anything is set.

    Raises
    ------
    ParamError
        ``--params NAME is for a copter; the vehicle is a plane (HEARTBEAT type 1): ...``, or
        a PX4 preset for an ArduPilot vehicle and the other way round.
    """
    from alphafence.mavlink.autopilots import NAMES

    wants = "px4" if VEHICLE[name] == "px4" else "ardupilot"
    if vehicle.autopilot != wants:
        fits = sorted(n for n, v in VEHICLE.items() if (v == "px4") == (vehicle.autopilot == "px4"))
        raise ParamError(
            f"--params {name} is for {NAMES[wants]}; the vehicle runs {NAMES[vehicle.autopilot]} "
            f"(its HEARTBEAT): use one of {', '.join(fits)}; nothing was sent"
        )
    if wants == "px4":
        return
    mav_type = await heartbeat_type(vehicle)
    kind = vehicle_kind(mav_type)
    if kind != VEHICLE[name]:
        fits = sorted(n for n, v in VEHICLE.items() if v == kind)
        raise ParamError(
            f"--params {name} is for a {VEHICLE[name]}; the vehicle is "
            f"{'a ' + kind if kind else 'no copter, plane or rover'} (HEARTBEAT type {mav_type})"
            + (f": use one of {', '.join(fits)}" if fits else "")
            + "; nothing was sent"
        )


@dataclass
class ParamReport:
    """The parameters as read back after setting them (name -> value)."""

    values: dict


async def apply_params(vehicle, values: dict) -> ParamReport:
    """Set each parameter, then read every one back; raise ParamError on any mismatch.

    A set the link reports failed because the vehicle answered with a value of its own (MAVSDK
    re-sends, then gives up) goes on to the next parameter: the read-back names every
    parameter that holds another value than the one set, whichever link it is.

    Parameters
    ----------
    vehicle : Vehicle
    values : dict
        Parameter name -> value.

    Raises
    ------
    ParamError
        A set or read that failed, or ``read back differs: NAME set A reads B, ...``.
    """
    for name, value in values.items():
        try:
            await _set(vehicle, name, value)
        except Exception as exc:
            if await _holds_other(vehicle, name, value):
                continue  # the read-back below says what it holds
            raise ParamError(f"setting {name} = {value} failed ({exc})") from None
    got = await read_params(vehicle, values)
    bad = {k: (v, got[k]) for k, v in values.items() if not _same(got[k], v)}
    if bad:
        raise ParamError(
            "read back differs: " + ", ".join(f"{k} set {a} reads {b}" for k, (a, b) in bad.items())
        )
    return ParamReport(got)


def _same(got, value) -> bool:
    return abs(float(got) - float(value)) <= 1e-4 * max(1.0, abs(value))


async def _holds_other(vehicle, name, value) -> bool:
    """Whether the vehicle answers for ``name`` with another value than ``value`` (False when
    it does not answer)."""
    try:
        return not _same(await _get(vehicle, name), value)
    except Exception:
        return False


async def read_params(vehicle, names) -> dict:
    """The vehicle's value of each parameter in ``names``; ParamError when one cannot be
    read."""
    out = {}
    for name in names:
        try:
            out[name] = await _get(vehicle, name)
        except Exception as exc:
            raise ParamError(f"reading {name} failed ({exc})") from None
    return out


# ArduPilot declares some integer parameters with a type MAVSDK does not expect (it reports
# WRONG_TYPE): try the natural type first, then the other.
async def _set(vehicle, name, value):
    first, second = ("int", "float") if name in INTEGER else ("float", "int")
    try:
        await _call(vehicle, "set", first, name, value)
    except Exception:
        await _call(vehicle, "set", second, name, value)


async def _get(vehicle, name):
    first, second = ("int", "float") if name in INTEGER else ("float", "int")
    try:
        return await _call(vehicle, "get", first, name)
    except Exception:
        return await _call(vehicle, "get", second, name)


def _call(vehicle, verb, kind, name, value=None):
    fn = getattr(vehicle.param, f"{verb}_param_{kind}")
    if verb == "get":
        return fn(name)
    return fn(name, int(value) if kind == "int" else float(value))


UNION_SINCE = (4, 5, 0)  # FENCE_OPTIONS bit 1 (ArduPilot PR 24379) is read from 4.5.0 on


async def firmware_version(vehicle, timeout: float = 3.0):
    """The autopilot's firmware ``(major, minor, patch)`` from AUTOPILOT_VERSION's
    ``flight_sw_version`` (asked for with MAV_CMD_REQUEST_MESSAGE), or None when none comes."""
    from alphafence.mavlink import ids

    sysid = await vehicle.system_id()

    async def first():
        async for m in vehicle.messages("AUTOPILOT_VERSION"):
            if m.system_id == sysid and isinstance(m.fields.get("flight_sw_version"), int):
                v = m.fields["flight_sw_version"]
                return (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF

    async def ask():
        while True:
            vehicle.send_command_long(
                ids.MAV_CMD_REQUEST_MESSAGE, ids.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            )
            await asyncio.sleep(0.5)

    asker = asyncio.ensure_future(ask())
    try:
        return await asyncio.wait_for(first(), timeout)
    except asyncio.TimeoutError:
        return None
    finally:
        asker.cancel()


async def inclusion_rule(vehicle):
    """How the vehicle reads several inclusions, by its firmware.

    Returns
    -------
    tuple
        ``(rule, options, why)``: ``"union"`` (ArduPilot 4.5.0 or later with FENCE_OPTIONS,
        whose bit 1 the upload sets) or ``"intersection"`` (PX4; ArduPilot without the
        parameter, older than 4.5.0, or whose version does not come), its FENCE_OPTIONS
        (None without), and the reason in words.
    """
    from alphafence.mavlink.autopilots import NAMES, inclusion_union_possible
    from alphafence.mavlink.inclusions import FENCE_OPTIONS

    autopilot = getattr(vehicle, "autopilot", "ardupilot")
    if not inclusion_union_possible(autopilot):
        return "intersection", None, f"{NAMES[autopilot]} reads them as their intersection"
    version = await firmware_version(vehicle)
    try:
        options = float(await _get(vehicle, FENCE_OPTIONS))
    except Exception:
        options = None
    said = "ArduPilot " + (".".join(map(str, version)) if version else "of unknown version")
    if options is None:
        return (
            "intersection",
            None,
            f"{said} has no FENCE_OPTIONS: it reads them as their intersection",
        )
    if version is None or version < UNION_SINCE:
        return (
            "intersection",
            options,
            (
                f"{said} has FENCE_OPTIONS but "
                + ("may not read" if version is None else "does not read")
                + " its union bit (ArduPilot 4.5.0 and later): it reads them as their intersection"
            ),
        )
    return "union", options, f"{said} reads them as their union with FENCE_OPTIONS bit 1"


async def vehicle_union(vehicle) -> bool:
    """Whether the vehicle reads its inclusions as their union: FENCE_OPTIONS bit 1 set, on
    firmware that reads it (:func:`inclusion_rule`)."""
    from alphafence.mavlink.inclusions import union_of

    rule, options, _ = await inclusion_rule(vehicle)
    return rule == "union" and union_of(options)


async def set_union(vehicle, options) -> ParamReport:
    """Set ``FENCE_OPTIONS``'s union bit (its other bits kept from ``options``) and read it
    back."""
    from alphafence.mavlink.inclusions import FENCE_OPTIONS, options_with_union

    return await apply_params(vehicle, {FENCE_OPTIONS: options_with_union(options)})
