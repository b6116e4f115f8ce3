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
    # GF_SOURCE 0: the fence is checked against the estimator's global position (1: raw GPS)
    return {"GF_ACTION": action, "GF_SOURCE": 0, "GF_MAX_VER_DIST": MAX_VER_DIST_M}


PRESETS = {f"px4-{what}": _preset(action) for what, action in _ACTION_OF.items()}
"""PX4's presets: name -> the parameters each sets, in the order set (``upload --params``)."""
INTEGER = {"GF_ACTION", "GF_SOURCE", "GF_PREDICT"}
INVALID_TEXT = "Geofence invalid"  # PX4's words when it discards an area as the fence loads


def describe(name: str) -> str:
    """A PX4 preset's parameters and what its GF_ACTION does, on one line.

    Examples
    --------
    >>> describe("px4-hold")
    'GF_ACTION=2 (Hold mode) GF_SOURCE=0 GF_MAX_VER_DIST=120'
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


def monotonic() -> float:
    """The clock :func:`confirm_kept`'s ``t0`` is read on."""
    return time.monotonic()
