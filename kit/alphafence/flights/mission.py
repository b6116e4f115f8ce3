"""Missions read as the positions they fly through, in the order they are flown, from
QGroundControl plans and QGC WPL files (both lat, lon; positions here are lon, lat).

Every mission item whose command flies to its params 5-7 is a position
(:func:`alphafence.mavlink.ids.flies_to_position`: waypoints, loiters, takeoffs, landings,
payload places...), flown as :mod:`alphafence.flights.mission_flight` has it: jumps followed,
each leg with its altitudes in the reference of the items' frame. Home's altitude AMSL is a
plan's ``plannedHomePosition`` altitude or a waypoint file's line 0 (in a frame AMSL); an
altitude of exactly 0 there, what planners write when they do not know it, is not known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.errors import InputError
from alphafence.fencefiles.qgc_wpl import wpl_records
from alphafence.flights.mission_flight import (
    FRAMES,
    MAX_POSITIONS,  # noqa: F401 (named here too)
    RTL_ALT_M,
    Step,
    Waypoint,
    fly,
)
from alphafence.geo.coords import checked_position
from alphafence.mavlink import ids
from alphafence.mavlink.ids import command_name
from alphafence.zones.jsonfile import read_json


@dataclass
class Mission:
    """A mission as flown: its positions and what is known of home's altitude.

    Attributes
    ----------
    waypoints : list of Waypoint
        In the order flown (:func:`read_mission`).
    home_amsl : float or None
        Home's altitude AMSL, metres, where the file gives it.
    """

    waypoints: list
    home_amsl: float | None = None


def read_mission(path, min_positions=2):
    """The positions a mission flies through, in the order flown (home first; RTL returns
    home; jumps followed).

    Parameters
    ----------
    path : str or Path
        A QGroundControl ``.plan`` (items nested in complex items included; items in
        QGroundControl's older forms, ``coordinate`` with four params, read as QGroundControl
        reads them) or a QGC WPL file.
    min_positions : int
        Fewer positions than this is an InputError.

    Returns
    -------
    list of Waypoint
        A loop flown several times is in it several times (at most until it repeats).
    """
    return load_mission(path, min_positions).waypoints


def load_mission(path, min_positions=2, rtl_alt_m=RTL_ALT_M) -> Mission:
    """A mission as flown (:func:`read_mission`), with home's altitude AMSL where the file
    gives it, and each leg's altitudes (see the module).

    Parameters
    ----------
    path : str or Path
    min_positions : int
    rtl_alt_m : float
        The altitude above home RTL climbs to at least (the vehicle's ``RTL_ALT``).

    Returns
    -------
    Mission
    """
    if is_wpl(path):
        home_amsl, steps = _wpl_steps(path)
        out = fly(path, steps, None, "seq", home_amsl, rtl_alt_m)
    else:
        home, home_amsl, steps = _plan_steps(path)
        out = fly(path, steps, home, "doJumpId", home_amsl, rtl_alt_m)
    if len(out) < min_positions:
        what = "no legs to check" if min_positions > 1 else "no positions to use"
        raise InputError(path, f"the mission has fewer than {min_positions} position(s): {what}")
    return Mission(out, home_amsl)


def is_wpl(path) -> bool:
    """Whether the mission file ``path`` is a QGC WPL file (else a QGroundControl plan).

    Raises
    ------
    InputError
        The file is missing or unreadable.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(16)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read ({exc})") from None
    return head.startswith("QGC WPL")


def _home_amsl(path, where, alt):
    """Home's altitude AMSL as given, or None: none, null, or exactly 0 (not known)."""
    if alt is None:
        return None
    if isinstance(alt, bool) or not isinstance(alt, (int, float)):
        raise InputError(path, f"home altitude must be a number or null, not {alt!r}", where)
    return float(alt) if math.isfinite(alt) and alt != 0 else None


# -- QGroundControl plans -----------------------------------------------------------------
def _flatten(items):
    for it in items:
        if isinstance(it, dict) and it.get("type") == "ComplexItem":
            transect = it.get("TransectStyleComplexItem")
            inner = transect.get("Items") if isinstance(transect, dict) else None
            if not isinstance(inner, list):
                inner = it.get("Items") if isinstance(it.get("Items"), list) else None
            yield (it, inner)
        else:
            yield (it, None)


def _number(path, where, what, v):
    """A param as QGroundControl reads it: a number, or null for NaN."""
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(path, f"{what} must be a number or null, not {v!r}", where)
    return float(v)


def _params(path, where, it):
    """An item's seven params, from any form QGroundControl reads (``MissionItem::load``):
    ``params`` of 7; ``params`` of 4 and ``coordinate`` [lat, lon, alt] (QGroundControl 3.2);
    ``param1``..``param4`` and ``coordinate`` (the first item form)."""
    params, coord = it.get("params"), it.get("coordinate")
    if params is None and all(f"param{k}" in it for k in range(1, 5)):
        params = [it[f"param{k}"] for k in range(1, 5)]
    if isinstance(params, list) and len(params) == 4 and coord is not None:
        if not isinstance(coord, list) or len(coord) < 2:
            raise InputError(path, f"coordinate must be [lat, lon, alt], not {coord!r}", where)
        params = [*params, *coord[:3], *[0.0] * (3 - len(coord[:3]))]
    if not isinstance(params, list) or len(params) != 7:
        raise InputError(path, "params must be a list of 7 values (or 4 and a coordinate)", where)
    return [_number(path, where, f"param {k + 1}", v) for k, v in enumerate(params)]


def _home(path, mission):
    """Home (or None) and its altitude AMSL (or None)."""
    home = mission.get("plannedHomePosition")
    if isinstance(home, dict):  # the first mission layout: home saved as an item
        home = home.get("coordinate")
    if isinstance(home, list) and len(home) >= 2 and (home[0] or home[1]):
        where = "plannedHomePosition"
        lon, lat = checked_position(path, where, home[0], home[1])
        amsl = _home_amsl(path, where, home[2]) if len(home) > 2 else None
        return Waypoint("home", lon, lat, 0.0, "home"), amsl
    return None, None


def _plan_steps(path):
    doc = read_json(path)
    mission = doc.get("mission") if isinstance(doc, dict) else None
    if not isinstance(mission, dict) or not isinstance(mission.get("items", []), list):
        raise InputError(path, "no mission section (not a QGroundControl plan?)")
    steps, n = [], 0

    def visit(items, prefix, top):
        nonlocal n
        for it, inner in _flatten(items):
            n += 1
            where = f"{prefix}item {n}"
            if not isinstance(it, dict):
                raise InputError(path, "mission item is not an object", where)
            if inner is not None:
                visit(inner, f"{where} (complex {it.get('complexItemType', '?')}) / ", False)
                continue
            if it.get("type") == "ComplexItem":
                raise InputError(
                    path, f"complex item {it.get('complexItemType', '?')!r} has no Items", where
                )
            cmd, frame = it.get("command"), it.get("frame")
            if isinstance(cmd, bool) or not isinstance(cmd, int):
                raise InputError(path, f"command must be a whole number, not {cmd!r}", where)
            if frame is not None and (isinstance(frame, bool) or not isinstance(frame, int)):
                raise InputError(path, f"frame must be a whole number, not {frame!r}", where)
            p = _params(path, where, it)
            # DO_JUMP names its target by doJumpId, among the plan's own (top-level) items
            key = it.get("doJumpId") if top else None
            key = key if isinstance(key, int) and not isinstance(key, bool) else None
            label = f"{where} ({command_name(cmd)})"
            steps.append(_step(path, where, label, cmd, p, key, frame))

    visit(mission.get("items", []), "", True)
    return (*_home(path, mission), steps)


def _step(path, where, label, cmd, p, key, frame):
    lat, lon = p[4], p[5]
    pos = None
    if ids.flies_to_position(cmd) and not (
        any(math.isnan(v) for v in (lat, lon)) or (lat == 0 and lon == 0)
    ):  # NaN or 0, 0: where the vehicle is (e.g. takeoff at the current position)
        pos = checked_position(path, where, lat, lon)
    return Step(where, label, cmd, pos, p[0], p[1], key, frame, p[6])


# -- QGC WPL files ------------------------------------------------------------------------
def _wpl_steps(path):
    """Home's altitude AMSL (line 0's, in a frame AMSL) and the steps; home is 0 above home."""
    steps, home_amsl = [], None
    for r in wpl_records(path):
        label = "home" if r.seq == 0 else f"seq {r.seq} ({command_name(r.command)})"
        p, frame = [*r.params, r.lat, r.lon, r.alt], r.frame
        if r.seq == 0:
            if FRAMES.get(frame) == "amsl":
                home_amsl = _home_amsl(path, r.where, r.alt)
            p[6], frame = 0.0, ids.MAV_FRAME_GLOBAL_RELATIVE_ALT
        steps.append(_step(path, r.where, label, r.command, p, r.seq, frame))
    return home_amsl, steps
