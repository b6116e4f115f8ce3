"""Missions read as the positions they fly through, in the order they are flown, from
QGroundControl plans and QGC WPL files (both lat, lon; positions here are lon, lat).

Every mission item whose command flies to its params 5-7 is a position
(:func:`alphafence.mavlink.ids.flies_to_position`: waypoints, loiters, takeoffs, landings,
payload places...). ``DO_JUMP`` and ``DO_JUMP_TAG`` are followed as ArduPilot runs them (the
jump taken its repeat count of times, then passed; -1 for ever), with a bound: a jump loop
that runs for ever is flown until it repeats, and after :data:`MAX_POSITIONS` positions every
jump left is passed (the legs a loop flies again are legs already flown).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.errors import InputError
from alphafence.formats.jsonfile import read_json
from alphafence.formats.qgc_wpl import wpl_records
from alphafence.geo.coords import checked_position
from alphafence.mavlink import ids
from alphafence.mavlink.ids import command_name

MAX_POSITIONS = 10_000
"""Positions flown before every jump still to come is passed instead of taken (a loop flown
again flies legs already flown; the bound keeps a flight path that ``compile --area`` buffers
short)."""

JUMPS = (ids.MAV_CMD_DO_JUMP, ids.MAV_CMD_DO_JUMP_TAG)


@dataclass
class Waypoint:
    """A position a mission flies through.

    Attributes
    ----------
    label : str
        Where it came from, for messages (``"home"``, ``"item 3 (waypoint)"``).
    lon, lat : float
        Degrees.
    """

    label: str  # "home", "item 3 (waypoint)", "seq 4 (takeoff)"
    lon: float
    lat: float


@dataclass(frozen=True)
class _Step:
    """One mission item as the flight follows it."""

    where: str  # for messages: "item 5", "line 7"
    label: str
    command: int
    position: tuple | None  # (lon, lat)
    p1: float
    p2: float
    key: int | None  # what a DO_JUMP names: the doJumpId (plans) or the seq (WPL)


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
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(16)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read ({exc})") from None
    if head.startswith("QGC WPL"):
        out = _fly(path, _wpl_steps(path), None, "seq")
    else:
        home, steps = _plan_steps(path)
        out = _fly(path, steps, home, "doJumpId")
    if len(out) < min_positions:
        what = "no legs to check" if min_positions > 1 else "no positions to use"
        raise InputError(path, f"the mission has fewer than {min_positions} position(s): {what}")
    return out


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
    home = mission.get("plannedHomePosition")
    if isinstance(home, dict):  # the first mission layout: home saved as an item
        home = home.get("coordinate")
    if isinstance(home, list) and len(home) >= 2 and (home[0] or home[1]):
        return Waypoint("home", *checked_position(path, "plannedHomePosition", home[0], home[1]))
    return None


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
            cmd = it.get("command")
            if isinstance(cmd, bool) or not isinstance(cmd, int):
                raise InputError(path, f"command must be a whole number, not {cmd!r}", where)
            p = _params(path, where, it)
            # DO_JUMP names its target by doJumpId, among the plan's own (top-level) items
            key = it.get("doJumpId") if top else None
            key = key if isinstance(key, int) and not isinstance(key, bool) else None
            steps.append(_step(path, where, f"{where} ({command_name(cmd)})", cmd, p, key))

    visit(mission.get("items", []), "", True)
    return _home(path, mission), steps


def _step(path, where, label, cmd, p, key):
    lat, lon = p[4], p[5]
    pos = None
    if ids.flies_to_position(cmd) and not (
        any(math.isnan(v) for v in (lat, lon)) or (lat == 0 and lon == 0)
    ):  # NaN or 0, 0: where the vehicle is (e.g. takeoff at the current position)
        pos = checked_position(path, where, lat, lon)
    return _Step(where, label, cmd, pos, p[0], p[1], key)


# -- QGC WPL files ------------------------------------------------------------------------
def _wpl_steps(path):
    steps = []
    for r in wpl_records(path):
        label = "home" if r.seq == 0 else f"seq {r.seq} ({command_name(r.command)})"
        p = [*r.params, r.lat, r.lon, r.alt]
        steps.append(_step(path, r.where, label, r.command, p, r.seq))
    return steps


# -- the flight -----------------------------------------------------------------------------
def _whole(v):
    return math.isfinite(v) and v == int(v)


def _targets(path, steps, key_name):
    """Where each jump goes: the step a DO_JUMP's param1 names (by ``key_name``), or the
    JUMP_TAG a DO_JUMP_TAG's param1 names."""
    by_key, tags = {}, {}
    for i, s in enumerate(steps):
        if s.key is not None:
            by_key.setdefault(s.key, i)
        if s.command == ids.MAV_CMD_JUMP_TAG and _whole(s.p1):
            tags.setdefault(int(s.p1), i)
    out = {}
    for i, s in enumerate(steps):
        if s.command not in JUMPS:
            continue
        word = "DO_JUMP" if s.command == ids.MAV_CMD_DO_JUMP else "DO_JUMP_TAG"
        if not _whole(s.p1):
            raise InputError(path, f"{word} target must be a whole number, not {s.p1:g}", s.where)
        t = int(s.p1)
        if s.command == ids.MAV_CMD_DO_JUMP_TAG:
            if t not in tags:
                raise InputError(path, f"DO_JUMP_TAG to tag {t}: no JUMP_TAG {t}", s.where)
            out[i] = tags[t]
        elif key_name == "seq" and t == 0:
            raise InputError(
                path, "DO_JUMP to seq 0 (home): ArduPilot jumps to mission items only", s.where
            )
        elif t not in by_key:
            raise InputError(path, f"DO_JUMP to {key_name} {t}: no such item", s.where)
        else:
            out[i] = by_key[t]
    return out


def _repeats(p2) -> float:
    """How often a jump is taken: its repeat count; -1 (any negative, or no number) for ever."""
    return float(int(p2)) if math.isfinite(p2) and p2 >= 0 else math.inf


def _fly(path, steps, home, key_name):
    """The positions flown, in order, following the jumps (see the module's notes)."""
    targets = _targets(path, steps, key_name)
    out = [home] if home is not None else []
    left, seen, i = {}, set(), 0
    while i < len(steps):
        s = steps[i]
        if i in targets:
            n = left.setdefault(i, _repeats(s.p2))
            if len(out) >= MAX_POSITIONS and n != math.inf:
                n = 0
            if n > 0:
                left[i] = n - 1
                last = (out[-1].label, out[-1].lon, out[-1].lat) if out else None
                state = (i, last, tuple(sorted(left.items())))
                if state in seen:  # flown exactly so before: the same legs from here on
                    break
                seen.add(state)
                i = targets[i]
                continue
        elif s.command == ids.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            if home is not None:
                out.append(Waypoint(f"{s.label} -> home", home.lon, home.lat))
        elif s.position is not None:
            out.append(Waypoint(s.label, *s.position))
            if home is None:
                home = out[-1]
        i += 1
    return out
