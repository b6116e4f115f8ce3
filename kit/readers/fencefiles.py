"""Read fence items back from a QGroundControl .plan or a QGC WPL 110 waypoint file."""

from __future__ import annotations

import math

from kit.coords import valid_lonlat
from kit.errors import InputError
from kit.readers import read_json
from kit.writers.mavlink_items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)

FENCE_COMMANDS = {
    POLYGON_INCLUSION,
    POLYGON_EXCLUSION,
    CIRCLE_INCLUSION,
    CIRCLE_EXCLUSION,
    RETURN_POINT,
}


def _latlon(path, where, pair):
    if not (
        isinstance(pair, list)
        and len(pair) >= 2
        and all(isinstance(v, (int, float)) for v in pair[:2])
    ):
        raise InputError(path, f"expected [lat, lon], got {pair!r}", where)
    lat, lon = float(pair[0]), float(pair[1])
    if not valid_lonlat(lon, lat):
        raise InputError(path, f"coordinate (lat {lat}, lon {lon}) out of range", where)
    return lon, lat


def read_plan_fence(path):
    doc = read_json(path)
    fence = doc.get("geoFence") if isinstance(doc, dict) else None
    if not isinstance(fence, dict):
        raise InputError(path, "no geoFence section (not a QGroundControl plan?)")
    items = []
    for k, poly in enumerate(fence.get("polygons", [])):
        where = f"geoFence polygon {k}"
        pts = poly.get("polygon") if isinstance(poly, dict) else None
        if not isinstance(pts, list) or len(pts) < 3:
            raise InputError(path, "a polygon needs at least 3 vertices", where)
        cmd = POLYGON_INCLUSION if poly.get("inclusion") else POLYGON_EXCLUSION
        for pair in pts:
            lon, lat = _latlon(path, where, pair)
            items.append(FenceItem(cmd, float(len(pts)), lon, lat))
    for k, circ in enumerate(fence.get("circles", [])):
        where = f"geoFence circle {k}"
        c = circ.get("circle") if isinstance(circ, dict) else None
        if not isinstance(c, dict):
            raise InputError(path, "circle entry without 'circle'", where)
        lon, lat = _latlon(path, where, c.get("center"))
        r = c.get("radius")
        if not isinstance(r, (int, float)) or not math.isfinite(r) or r <= 0:
            raise InputError(path, f"radius must be a positive number, not {r!r}", where)
        items.append(
            FenceItem(
                CIRCLE_INCLUSION if circ.get("inclusion") else CIRCLE_EXCLUSION, float(r), lon, lat
            )
        )
    return items


def wpl_rows(path):
    """The rows of a QGC WPL waypoint file: (where, seq, command, param1, lat, lon), with
    one-line errors for unreadable files, wrong field counts and non-numbers."""
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
            yield where, int(f[0]), int(f[3]), float(f[4]), float(f[8]), float(f[9])
        except ValueError:
            raise InputError(path, "non-numeric field", where) from None


def read_waypoints_fence(path):
    items = []
    for where, _seq, cmd, p1, lat, lon in wpl_rows(path):
        if cmd not in FENCE_COMMANDS:
            raise InputError(path, f"command {cmd} is not a fence item (5000-5004)", where)
        if not valid_lonlat(lon, lat):
            raise InputError(path, f"coordinate (lat {lat}, lon {lon}) out of range", where)
        items.append(FenceItem(cmd, p1, lon, lat))
    return items
