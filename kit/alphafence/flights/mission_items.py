"""A mission's items as a vehicle stores them, from a QGroundControl plan or a QGC WPL file:
what an upload sends, in order, home first (lat, lon as both files have them).

A plan's top-level simple items are taken as they are; its home is ``plannedHomePosition``
(AMSL). A complex item (a survey, a corridor scan) is refused: QGroundControl turns it into
items when it uploads, and those are not in the file.
"""

from __future__ import annotations

import math

from alphafence.errors import InputError
from alphafence.fencefiles.qgc_wpl import WplRow, wpl_records
from alphafence.flights.mission import _params, is_wpl
from alphafence.mavlink import ids
from alphafence.zones.jsonfile import read_json


def mission_rows(path) -> list[WplRow]:
    """The items a mission file uploads, home (seq 0) first.

    Parameters
    ----------
    path : str or Path
        A QGroundControl ``.plan`` or a QGC WPL file (told by its first line).

    Returns
    -------
    list of WplRow
        ``seq`` 0, 1, 2... in upload order; a plan without a planned home has a home of
        0, 0 (the vehicle replaces it with its own when it arms).

    Raises
    ------
    InputError
        One line naming the file and the item: not a mission, a complex item, no items.
    """
    rows = list(wpl_records(path)) if is_wpl(path) else _plan_rows(path)
    if len(rows) < 2:
        raise InputError(path, "the mission has no items to fly")
    return [row._replace(seq=seq) for seq, row in enumerate(rows)]


def _plan_rows(path) -> list[WplRow]:
    doc = read_json(path)
    mission = doc.get("mission") if isinstance(doc, dict) else None
    items = mission.get("items", []) if isinstance(mission, dict) else None
    if not isinstance(items, list):
        raise InputError(path, "no mission section (not a QGroundControl plan?)")
    home = mission.get("plannedHomePosition")
    lat, lon, alt = (home + [0.0, 0.0, 0.0])[:3] if isinstance(home, list) else (0.0, 0.0, 0.0)
    rows = [WplRow("plannedHomePosition", 0, ids.MAV_FRAME_GLOBAL, ids.MAV_CMD_NAV_WAYPOINT,
                   (0.0, 0.0, 0.0, 0.0), _num(lat), _num(lon), _num(alt))]  # fmt: skip
    for n, it in enumerate(items, start=1):
        where = f"item {n}"
        if not isinstance(it, dict):
            raise InputError(path, "mission item is not an object", where)
        if it.get("type") == "ComplexItem":
            raise InputError(
                path,
                f"complex item {it.get('complexItemType', '?')!r}: QGroundControl makes its "
                "items as it uploads; save the mission as a QGC WPL file from QGroundControl",
                where,
            )
        cmd, frame = it.get("command"), it.get("frame", ids.MAV_FRAME_GLOBAL_RELATIVE_ALT)
        if isinstance(cmd, bool) or not isinstance(cmd, int):
            raise InputError(path, f"command must be a whole number, not {cmd!r}", where)
        if isinstance(frame, bool) or not isinstance(frame, int):
            raise InputError(path, f"frame must be a whole number, not {frame!r}", where)
        p = _params(path, where, it)  # params 1-4 may be NaN (MAVLink: "unchanged")
        lat, lon, alt = (0.0 if math.isnan(v) else v for v in p[4:])
        rows.append(WplRow(where, n, frame, cmd, tuple(p[:4]), lat, lon, alt))
    return rows


def _num(v) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else 0.0
