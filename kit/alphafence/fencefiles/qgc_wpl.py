"""QGC WPL 110 text files: ArduPilot's and MAVProxy's fence and mission files (lat, lon order).

Each line after the ``QGC WPL 110`` header: seq, current, frame, command, param1..4, lat, lon,
alt, autocontinue, tab separated. Fence items use frame 0 (MAV_FRAME_GLOBAL), as ArduPilot
reports them; a mission's line 0 is home. This module writes and reads both.
"""

from __future__ import annotations

from typing import NamedTuple

from alphafence.errors import InputError
from alphafence.geo.coords import checked_position, latlon
from alphafence.mavlink import ids
from alphafence.mavlink.items import FenceItem

HEADER = "QGC WPL 110"


def rows_text(rows) -> str:
    """QGC WPL 110 text for rows ``(seq, current, frame, command, p1, p2, p3, p4, lat, lon,
    alt)``: integers for the first four fields, 6 decimals for params and altitude, 8 for
    latitude and longitude, autocontinue 1."""
    lines = [HEADER]
    for r in rows:
        lines.append(
            "\t".join(
                [str(int(v)) for v in r[:4]]
                + [f"{float(v):.6f}" for v in r[4:8]]
                + [f"{float(r[8]):.8f}", f"{float(r[9]):.8f}", f"{float(r[10]):.6f}", "1"]
            )
        )
    return "\n".join(lines) + "\n"


def waypoints_text(items) -> str:
    """A fence file: one line per FenceItem, numbered from 0, frame MAV_FRAME_GLOBAL.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> text = waypoints_text([FenceItem(5004, 50.0, 14.5, 35.9)])
    >>> print(text, end="")  # tab separated  # doctest: +NORMALIZE_WHITESPACE
    QGC WPL 110
    0	0	0	5004	50.000000	0.000000	0.000000	0.000000	35.90000000	14.50000000	0.000000	1
    """
    return rows_text(
        (seq, 0, ids.MAV_FRAME_GLOBAL, it.command, it.param1, 0, 0, 0, it.lat, it.lon, 0)
        for seq, it in enumerate(items)
    )


def mission_waypoints_text(items, home_lonlat) -> str:
    """A mission file: line 0 is home, then the QGC plan SimpleItems ``items`` (as
    ``qgc_plan.mission_items`` makes them)."""
    lat, lon = latlon([home_lonlat])[0]
    rows = [(0, 1, ids.MAV_FRAME_GLOBAL, ids.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, lat, lon, 0)]
    for seq, it in enumerate(items, start=1):
        p = [0.0 if v is None else float(v) for v in it["params"]]
        rows.append((seq, 0, it["frame"], it["command"], *p[:7]))
    return rows_text(rows)


class WplRow(NamedTuple):
    """One line of a QGC WPL file, as read (``where`` names the line for messages)."""

    where: str
    seq: int
    frame: int
    command: int
    params: tuple  # param1..param4
    lat: float
    lon: float
    alt: float


def wpl_records(path):
    """The rows of a QGC WPL file as :class:`WplRow`, in file order.

    Unreadable files, a missing header, wrong field counts and non-numbers raise a one-line
    InputError naming the line.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read ({exc})") from None
    if not lines or not lines[0].startswith("QGC WPL"):
        raise InputError(path, "not a QGC WPL waypoint file (first line must be 'QGC WPL 110')")
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        where = f"line {n}"
        f = line.split()
        if len(f) != 12:
            raise InputError(path, f"expected 12 fields, got {len(f)}", where)
        try:
            seq, frame, command = int(f[0]), int(f[2]), int(f[3])
            params = tuple(float(v) for v in f[4:8])
            lat, lon, alt = float(f[8]), float(f[9]), float(f[10])
        except ValueError:
            raise InputError(path, "non-numeric field", where) from None
        yield WplRow(where, seq, frame, command, params, lat, lon, alt)


def wpl_rows(path):
    """The rows of a QGC WPL file: ``(where, seq, command, param1, lat, lon)``.

    Unreadable files, a missing header, wrong field counts and non-numbers raise a one-line
    InputError naming the line.
    """
    for r in wpl_records(path):
        yield r.where, r.seq, r.command, r.params[0], r.lat, r.lon


def read_waypoints_fence(path):
    """The fence items of a QGC WPL fence file (commands 5000-5004 only), as FenceItems."""
    items = []
    for where, _seq, cmd, p1, lat, lon in wpl_rows(path):
        if cmd not in ids.FENCE_COMMANDS:
            raise InputError(path, f"command {cmd} is not a fence item (5000-5004)", where)
        lon, lat = checked_position(path, where, lat, lon)
        items.append(FenceItem(cmd, p1, lon, lat))
    return items
