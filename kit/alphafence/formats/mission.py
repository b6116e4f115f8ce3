"""Missions read as the positions they fly through, from QGroundControl plans and QGC WPL
files (both lat, lon; positions here are lon, lat)."""

from __future__ import annotations

from dataclasses import dataclass

from alphafence.errors import InputError
from alphafence.formats.jsonfile import read_json
from alphafence.formats.qgc_wpl import wpl_rows
from alphafence.geo.coords import checked_position
from alphafence.mavlink import ids
from alphafence.mavlink.ids import command_name


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


def read_mission(path, min_positions=2):
    """The positions a mission flies through, in order (home first; RTL returns home).

    Parameters
    ----------
    path : str or Path
        A QGroundControl ``.plan`` (items nested in complex items included) or a QGC WPL file.
    min_positions : int
        Fewer positions than this is an InputError.

    Returns
    -------
    list of Waypoint
    """
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(16)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read ({exc})") from None
    out = _read_wpl(path) if head.startswith("QGC WPL") else _read_plan(path)
    if len(out) < min_positions:
        what = "no legs to check" if min_positions > 1 else "no positions to use"
        raise InputError(path, f"the mission has fewer than {min_positions} position(s): {what}")
    return out


def _flatten(items):
    for it in items:
        if isinstance(it, dict) and it.get("type") == "ComplexItem":
            inner = (it.get("TransectStyleComplexItem") or {}).get("Items")
            if not isinstance(inner, list):
                inner = it.get("Items") if isinstance(it.get("Items"), list) else None
            yield (it, inner)
        else:
            yield (it, None)


def _read_plan(path):
    doc = read_json(path)
    mission = doc.get("mission") if isinstance(doc, dict) else None
    if not isinstance(mission, dict) or not isinstance(mission.get("items", []), list):
        raise InputError(path, "no mission section (not a QGroundControl plan?)")
    out = []
    home = mission.get("plannedHomePosition")
    home_wp = None
    if isinstance(home, list) and len(home) >= 2 and (home[0] or home[1]):
        home_wp = Waypoint("home", *checked_position(path, "plannedHomePosition", home[0], home[1]))
        out.append(home_wp)
    n = 0

    def visit(items, prefix):
        nonlocal n, home_wp
        for it, inner in _flatten(items):
            n += 1
            where = f"{prefix}item {n}"
            if not isinstance(it, dict):
                raise InputError(path, "mission item is not an object", where)
            if inner is not None:
                visit(inner, f"{where} (complex {it.get('complexItemType', '?')}) / ")
                continue
            if it.get("type") == "ComplexItem":
                raise InputError(
                    path, f"complex item {it.get('complexItemType', '?')!r} has no Items", where
                )
            cmd = it.get("command")
            params = it.get("params")
            label = f"{where} ({command_name(cmd)})"
            if cmd == ids.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                if home_wp is not None:
                    out.append(Waypoint(f"{label} -> home", home_wp.lon, home_wp.lat))
                continue
            if cmd not in ids.NAV_POSITION_COMMANDS:
                continue
            if not isinstance(params, list) or len(params) < 7:
                raise InputError(path, "params must be a list of 7 values", where)
            lat, lon = params[4], params[5]
            if (lat in (0, None)) and (lon in (0, None)):
                continue  # e.g. takeoff at the current position
            out.append(Waypoint(label, *checked_position(path, where, lat, lon)))
            if home_wp is None:
                home_wp = out[-1]

    visit(mission.get("items", []), "")
    return out


def _read_wpl(path):
    out = []
    home = None
    for where, seq, cmd, _p1, lat, lon in wpl_rows(path):
        label = "home" if seq == 0 else f"seq {seq} ({command_name(cmd)})"
        if cmd == ids.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            if home is not None:
                out.append(Waypoint(f"{label} -> home", home.lon, home.lat))
            continue
        if cmd not in ids.NAV_POSITION_COMMANDS or (lat == 0 and lon == 0):
            continue
        out.append(Waypoint(label, *checked_position(path, where, lat, lon)))
        if home is None:
            home = out[-1]
    return out
