"""Fence parameter profiles (AC_Fence), set and read back."""

from __future__ import annotations

from dataclasses import dataclass

from alphafence.errors import VehicleError

# FENCE_TYPE bits: 1 max altitude, 2 circle around home, 4 polygons and circles, 8 min altitude.
# FENCE_ACTION (Copter): 0 report, 1 RTL or land, 2 land, 3 SmartRTL/RTL/land, 4 brake or land.
PROFILES = {
    "copter-rtl": {
        "FENCE_ENABLE": 1,
        "FENCE_TYPE": 5,
        "FENCE_ACTION": 1,
        "FENCE_MARGIN": 2.0,
        "FENCE_ALT_MAX": 120.0,
    },
    "copter-brake": {
        "FENCE_ENABLE": 1,
        "FENCE_TYPE": 5,
        "FENCE_ACTION": 4,
        "FENCE_MARGIN": 2.0,
        "FENCE_ALT_MAX": 120.0,
    },
    "copter-land": {
        "FENCE_ENABLE": 1,
        "FENCE_TYPE": 5,
        "FENCE_ACTION": 2,
        "FENCE_MARGIN": 2.0,
        "FENCE_ALT_MAX": 120.0,
    },
    "report-only": {
        "FENCE_ENABLE": 1,
        "FENCE_TYPE": 5,
        "FENCE_ACTION": 0,
        "FENCE_MARGIN": 2.0,
        "FENCE_ALT_MAX": 120.0,
    },
}
INTEGER = {"FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "BRD_SD_FENCE"}

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
