"""What uploading a fence to PX4 takes besides the mission protocol: its home, its parameter
presets, and the confirmation that it keeps every area it was sent.

PX4 accepts a fence item by item (``MISSION_ACK`` 0) and only then, loading it, discards each
area home breaches (:mod:`alphafence.onboard.rules`), saying so in its log alone. The kit
therefore reads PX4's home before anything is sent and refuses such a fence
(:func:`check_home`), and after the read-back reads home again and listens for PX4's word
(:func:`confirm_kept`).
"""

from __future__ import annotations

import asyncio
import time

from alphafence.errors import VehicleError
from alphafence.mavlink import ids

# GF_ACTION's values (PX4's navigator/geofence_params.yaml)
GF_ACTIONS = {0: "None", 1: "Warning", 2: "Hold mode", 3: "Return mode", 4: "Terminate",
              5: "Land mode"}  # fmt: skip
_ACTION_OF = {"warn": 1, "hold": 2, "return": 3, "land": 5}
MAX_VER_DIST_M = 120.0  # as the ArduPilot presets' FENCE_ALT_MAX: 120 m above home


def _preset(action: int) -> dict:
    # GF_SOURCE 0: the fence is checked against the estimator's global position (1: raw GPS);
    # GF_PREDICT 1: against where the vehicle would stop (its default, 0, acts at the fence
    # itself and the vehicle then brakes past it: STOP_OVERSHOOT_M)
    return {"GF_ACTION": action, "GF_SOURCE": 0, "GF_PREDICT": 1,
            "GF_MAX_VER_DIST": MAX_VER_DIST_M}  # fmt: skip


PRESETS = {f"px4-{what}": _preset(action) for what, action in _ACTION_OF.items()}
"""PX4's presets: name -> the parameters each sets, in the order set (``upload --params``)."""
INTEGER = {"GF_ACTION", "GF_SOURCE", "GF_PREDICT"}

# How far past the fence a PX4 quadrotor goes when PX4 alone acts on it (GF_ACTION 2, Hold),
# flown straight at it at each ground speed (m/s): the deepest position past the fence, metres,
# measured on PX4 SITL (SIH quadrotor, no wind; tests/test_px4_flight_sitl.py), by GF_PREDICT.
# With GF_PREDICT 0 (PX4's default): 8.4 m at 5 m/s, 23.3-25.2 m at 10 m/s; with 1 (the
# presets'): 1.0-2.2 m and 1.6-3.4 m. The keep-out margin needs the overshoot plus what is left
# for position error and wind.
STOP_OVERSHOOT_M = {0: {5.0: 9.0, 10.0: 26.0}, 1: {5.0: 3.0, 10.0: 4.0}}
INVALID_TEXT = "Geofence invalid"  # PX4's words when it discards an area as the fence loads


def describe(name: str) -> str:
    """A PX4 preset's parameters and what its GF_ACTION does, on one line.

    Examples
    --------
    >>> describe("px4-hold")
    'GF_ACTION=2 (Hold mode) GF_SOURCE=0 GF_PREDICT=1 GF_MAX_VER_DIST=120'
    """
    return " ".join(
        f"{k}={v:g}" + (f" ({GF_ACTIONS[v]})" if k == "GF_ACTION" else "")
        for k, v in PRESETS[name].items()
    )


async def home_position(vehicle, timeout: float = 10.0) -> tuple:
    """The vehicle's home ``(lon, lat)`` in degrees, from HOME_POSITION (asked for with
    MAV_CMD_REQUEST_MESSAGE, every second until it comes).

    Raises
    ------
    VehicleError
        No home within ``timeout`` (no GPS fix yet).
    """
    sysid = await vehicle.system_id()

    async def first():
        async for m in vehicle.messages("HOME_POSITION"):
            if m.system_id == sysid:
                return m.fields["longitude"] / 1e7, m.fields["latitude"] / 1e7

    async def ask():
        while True:
            vehicle.send_command_long(ids.MAV_CMD_REQUEST_MESSAGE, ids.MAVLINK_MSG_ID_HOME_POSITION)
            await asyncio.sleep(1.0)

    asker = asyncio.ensure_future(ask())
    try:
        return await asyncio.wait_for(first(), timeout)
    except asyncio.TimeoutError:
        raise VehicleError(
            f"no home position from the vehicle within {timeout:g} s (no GPS fix yet?): PX4 "
            "drops every fence area its home breaches, so the kit checks home first; "
            "nothing was sent"
        ) from None
    finally:
        asker.cancel()


def _where(areas, home) -> str:
    lon, lat = home
    names = ", ".join(f"{a.name} ({'outside' if a.inclusion else 'inside'})" for a in areas[:4]) + (
        f" and {len(areas) - 4} more" if len(areas) > 4 else ""
    )
    return f"home {lat:.7f},{lon:.7f} breaches {names}"


async def check_home(vehicle, items, timeout: float = 10.0) -> tuple:
    """Refuse, before anything is sent, a fence PX4 would keep only in part: one with an area
    its home breaches. Returns home ``(lon, lat)``.

    Raises
    ------
    VehicleError
        ``PX4 would discard ... : home 35.8989000,14.4500000 breaches onboard inclusion
        polygon 1 (items 0-5) (outside); nothing was sent``.
    """
    from alphafence.onboard.rules import areas_breached_at

    home = await home_position(vehicle, timeout)
    areas = areas_breached_at(items, *home)
    if areas:
        raise VehicleError(
            f"PX4 would drop {len(areas)} area{'s' if len(areas) > 1 else ''} of this fence as "
            f"it loads it and fly without {'them' if len(areas) > 1 else 'it'}: "
            f"{_where(areas, home)}; nothing was sent"
        )
    return home


async def confirm_kept(vehicle, items, t0: float, settle: float = 1.0) -> None:
    """After the upload and its read-back: that PX4 keeps every area. Home is read again (it
    may have moved since :func:`check_home`) and PX4's own words since ``t0`` (monotonic)
    are read.

    Raises
    ------
    VehicleError
        Saying what the vehicle holds: every item was stored, but PX4 discards the areas
        named.
    """
    from alphafence.onboard.rules import areas_breached_at

    home = await home_position(vehicle)
    areas = areas_breached_at(items, *home)
    said = [t for t in await vehicle.texts_since(t0, settle) if INVALID_TEXT in t]
    if areas or said:
        raise VehicleError(
            f"the vehicle stored all {len(items)} items and read them back, but PX4 discards "
            + (_where(areas, home) if areas else "an area")
            + (f" (it says: {said[0].strip()})" if said else "")
            + ": upload a fence whose areas home does not breach"
        )


async def pause(vehicle, at=None) -> None:
    """Stop a PX4 vehicle where it is, whatever it is doing: MAV_CMD_DO_REPOSITION with no
    position (QGroundControl's pause), which PX4 takes as "hold here" and switches to Hold.
    Its Hold mode alone does not do it: a vehicle already in Hold flying to a reposition
    target (a goto) keeps flying to it. MAVSDK's link carries no NaN in a command: there it is
    a goto to ``at``, ``(lat, lon, alt_amsl_m)``, where the vehicle was last seen.

    Raises
    ------
    VehicleError
        PX4 refused the command, or no position ``at`` for MAVSDK's link.
    """
    nan = float("nan")
    if vehicle.kind == "mavsdk":
        if at is None or any(v is None for v in at):
            raise VehicleError("no position of the vehicle yet to hold it at")
        await vehicle.action.goto_location(float(at[0]), float(at[1]), float(at[2]), nan)
        return
    result = await vehicle.command_long(
        ids.MAV_CMD_DO_REPOSITION, -1, ids.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, nan, nan, nan,
        nan,
    )  # fmt: skip
    if result != ids.MAV_RESULT_ACCEPTED:
        raise VehicleError(f"PX4 refused to hold where it is (MAV_RESULT {result})")


async def reposition(vehicle, lat, lon, alt_amsl_m, yaw_deg=float("nan")) -> None:
    """Fly a PX4 vehicle to ``(lat, lon)`` at ``alt_amsl_m``: MAV_CMD_DO_REPOSITION as a
    COMMAND_INT (the position in MAVLink's integers), as MAVSDK sends its goto; PX4 flies
    there in Hold.

    Raises
    ------
    VehicleError
        PX4 refused it.
    """
    result = await vehicle.command_int(
        ids.MAV_CMD_DO_REPOSITION, ids.MAV_FRAME_GLOBAL,
        (-1, ids.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, yaw_deg), lat, lon, alt_amsl_m,
    )  # fmt: skip
    if result != ids.MAV_RESULT_ACCEPTED:
        raise VehicleError(f"PX4 refused the reposition (MAV_RESULT {result})")


SET_CURRENT_TRIES = 3
SET_CURRENT_WAIT_S = 1.5  # for the MISSION_CURRENT that says it (PX4 streams it at 1 Hz too)


async def set_current(v, index: int) -> None:
    """Make mission item ``index`` the one PX4 flies to next, through the pymavlink link
    ``v``: MISSION_SET_CURRENT until PX4's MISSION_CURRENT says so, as MAVSDK does (PX4 does not
    take MAV_CMD_DO_SET_MISSION_CURRENT: "command 224 unsupported").

    Raises
    ------
    VehicleError
        PX4 never said it.
    """
    sysid, compid = v.target

    async def said(queue):
        while not (v.from_autopilot(m := await queue.get()) and int(m.seq) == index):
            pass

    with v.bus.subscribe("MISSION_CURRENT") as queue:
        for _ in range(SET_CURRENT_TRIES):
            v.link.send(v.link.mav.mission_set_current_encode(sysid, compid, index))
            try:
                return await asyncio.wait_for(said(queue), SET_CURRENT_WAIT_S)
            except asyncio.TimeoutError:
                pass
    raise VehicleError(f"PX4 did not make mission item {index} its current one")


def monotonic() -> float:
    """The clock :func:`confirm_kept`'s ``t0`` is read on."""
    return time.monotonic()
