"""Missions: write a routed mission (QGC .plan items, QGC WPL 110), read any mission back
as a list of positions, and check its legs against keep-out fences.

Plans and waypoint files store (lat, lon); positions here are (lon, lat), converted through
``kit.coords``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from kit.coords import latlon, valid_lonlat
from kit.errors import InputError
from kit.frame import LocalFrame

NAV_WAYPOINT = 16
NAV_LOITER_UNLIM = 17
NAV_LOITER_TURNS = 18
NAV_LOITER_TIME = 19
NAV_RETURN_TO_LAUNCH = 20
NAV_LAND = 21
NAV_TAKEOFF = 22
NAV_LOITER_TO_ALT = 31
NAV_SPLINE_WAYPOINT = 82
NAV_VTOL_TAKEOFF = 84
NAV_VTOL_LAND = 85
NAV_POSITIONS = {
    NAV_WAYPOINT,
    NAV_LOITER_UNLIM,
    NAV_LOITER_TURNS,
    NAV_LOITER_TIME,
    NAV_LAND,
    NAV_TAKEOFF,
    NAV_LOITER_TO_ALT,
    NAV_SPLINE_WAYPOINT,
    NAV_VTOL_TAKEOFF,
    NAV_VTOL_LAND,
}
COMMAND_NAMES = {
    NAV_WAYPOINT: "waypoint",
    NAV_LOITER_UNLIM: "loiter",
    NAV_LOITER_TURNS: "loiter turns",
    NAV_LOITER_TIME: "loiter time",
    NAV_RETURN_TO_LAUNCH: "RTL",
    NAV_LAND: "land",
    NAV_TAKEOFF: "takeoff",
    NAV_LOITER_TO_ALT: "loiter to alt",
    NAV_SPLINE_WAYPOINT: "spline waypoint",
    NAV_VTOL_TAKEOFF: "VTOL takeoff",
    NAV_VTOL_LAND: "VTOL land",
}
FRAME_GLOBAL = 0
FRAME_MISSION = 2
FRAME_GLOBAL_RELATIVE_ALT = 3


# -- writing ----------------------------------------------------------------------------
def _simple(seq, command, frame, lonlat, alt):
    if lonlat is None:
        params = [0, 0, 0, 0, 0, 0, 0]
    else:
        lat, lon = latlon([lonlat])[0]
        params = [0, 0, 0, None, round(lat, 7), round(lon, 7), float(alt)]
    item = {
        "autoContinue": True,
        "command": command,
        "doJumpId": seq,
        "frame": frame,
        "params": params,
        "type": "SimpleItem",
    }
    if lonlat is not None:
        item.update({"AMSLAltAboveTerrain": None, "Altitude": float(alt), "AltitudeMode": 1})
    return item


def mission_items(path_lonlat, alt, fly_back=True):
    """QGC SimpleItems: takeoff at the first position, a waypoint at every later one, RTL.
    Positions use frame 3 (altitude relative to home); RTL has no position (frame 2, as
    QGroundControl writes it). RTL flies straight home, so with ``fly_back`` the mission
    first flies the route back to its start and RTL only lands there."""
    pts = np.asarray(path_lonlat, float).reshape(-1, 2)
    if fly_back and len(pts) > 1:
        pts = np.concatenate([pts, pts[-2::-1]])
    items = [_simple(1, NAV_TAKEOFF, FRAME_GLOBAL_RELATIVE_ALT, pts[0], alt)]
    for p in pts[1:]:
        items.append(_simple(len(items) + 1, NAV_WAYPOINT, FRAME_GLOBAL_RELATIVE_ALT, p, alt))
    items.append(_simple(len(items) + 1, NAV_RETURN_TO_LAUNCH, FRAME_MISSION, None, 0))
    return items


def mission_waypoints_text(items, home_lonlat) -> str:
    """QGC WPL 110 text: line 0 is home, then the items (lat, lon order, 1e-7 degrees)."""
    lat, lon = latlon([home_lonlat])[0]
    rows = [[0, 1, FRAME_GLOBAL, NAV_WAYPOINT, 0, 0, 0, 0, lat, lon, 0.0, 1]]
    for seq, it in enumerate(items, start=1):
        p = [0.0 if v is None else float(v) for v in it["params"]]
        rows.append([seq, 0, it["frame"], it["command"], *p[:4], p[4], p[5], p[6], 1])
    lines = ["QGC WPL 110"]
    for r in rows:
        lines.append(
            "\t".join(
                [str(int(v)) for v in r[:4]]
                + [f"{float(v):.6f}" for v in r[4:8]]
                + [f"{float(r[8]):.8f}", f"{float(r[9]):.8f}", f"{float(r[10]):.6f}", "1"]
            )
        )
    return "\n".join(lines) + "\n"


# -- reading ----------------------------------------------------------------------------
@dataclass
class Waypoint:
    label: str  # "home", "item 3 (waypoint)", "seq 4 (takeoff)"
    lon: float
    lat: float


def read_mission(path, min_positions=2):
    """The positions a mission flies through, in order (home first; RTL returns home)."""
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


def _position(path, where, lat, lon):
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (lat, lon)):
        raise InputError(path, f"non-numeric position ({lat!r}, {lon!r})", where)
    if not valid_lonlat(lon, lat):
        raise InputError(path, f"coordinate (lat {lat}, lon {lon}) out of range", where)
    return float(lon), float(lat)


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
    from kit.readers import read_json

    doc = read_json(path)
    mission = doc.get("mission") if isinstance(doc, dict) else None
    if not isinstance(mission, dict) or not isinstance(mission.get("items", []), list):
        raise InputError(path, "no mission section (not a QGroundControl plan?)")
    out = []
    home = mission.get("plannedHomePosition")
    home_wp = None
    if isinstance(home, list) and len(home) >= 2 and (home[0] or home[1]):
        home_wp = Waypoint("home", *_position(path, "plannedHomePosition", home[0], home[1]))
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
            label = f"{where} ({COMMAND_NAMES.get(cmd, f'command {cmd}')})"
            if cmd == NAV_RETURN_TO_LAUNCH:
                if home_wp is not None:
                    out.append(Waypoint(f"{label} -> home", home_wp.lon, home_wp.lat))
                continue
            if cmd not in NAV_POSITIONS:
                continue
            if not isinstance(params, list) or len(params) < 7:
                raise InputError(path, "params must be a list of 7 values", where)
            lat, lon = params[4], params[5]
            if (lat in (0, None)) and (lon in (0, None)):
                continue  # e.g. takeoff at the current position
            out.append(Waypoint(label, *_position(path, where, lat, lon)))
            if home_wp is None:
                home_wp = out[-1]

    visit(mission.get("items", []), "")
    return out


def _read_wpl(path):
    from kit.readers.fencefiles import wpl_rows

    out = []
    home = None
    for where, seq, cmd, _p1, lat, lon in wpl_rows(path):
        label = "home" if seq == 0 else f"seq {seq} ({COMMAND_NAMES.get(cmd, f'command {cmd}')})"
        if cmd == NAV_RETURN_TO_LAUNCH:
            if home is not None:
                out.append(Waypoint(f"{label} -> home", home.lon, home.lat))
            continue
        if cmd not in NAV_POSITIONS or (lat == 0 and lon == 0):
            continue
        out.append(Waypoint(label, *_position(path, where, lat, lon)))
        if home is None:
            home = out[-1]
    return out


# -- checking ---------------------------------------------------------------------------
@dataclass
class LegIssue:
    leg: int  # 1-based
    start: str
    end: str
    fence: str
    distance_m: float  # 0 when the leg crosses the fence
    crosses: bool


def check_legs(waypoints, records, clearance=20.0, fence_label=None):
    """Legs between consecutive waypoints that cross (distance 0) or graze (closer than
    ``clearance``) a keep-out fence, computed exactly in one local metric frame.
    Returns (issues, legs, warning_legs)."""
    from kit.route.fenceroute import fence_label as default_label

    label = fence_label or default_label
    keep_out = [r for r in records if r.kind == "keep_out"]
    warning = [r for r in records if r.kind == "warning"]
    pts = np.array([(w.lon, w.lat) for w in waypoints], float)
    legs = list(zip(range(1, len(pts)), waypoints[:-1], waypoints[1:]))
    if not keep_out and not warning:
        return [], legs, set()
    coords = np.concatenate([pts] + [shapely.get_coordinates(r.geometry) for r in keep_out])
    frame = LocalFrame.around_coords(coords)
    x, y = frame.to_local(pts[:, 0], pts[:, 1])
    xy = np.column_stack([x, y])
    segs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    issues = []
    if keep_out:
        ko = frame.geom_to_local(np.array([r.geometry for r in keep_out], dtype=object))
        tree = shapely.STRtree(ko)
        i, j = tree.query(segs, predicate="dwithin", distance=clearance)
        d = shapely.distance(segs[i], ko[j])
        for a, b, dist in sorted(zip(i.tolist(), j.tolist(), d.tolist())):
            issues.append(
                LegIssue(
                    a + 1,
                    waypoints[a].label,
                    waypoints[a + 1].label,
                    label(keep_out[b]),
                    float(dist),
                    dist <= 0.0,
                )
            )
    warning_legs = set()
    if warning:
        wa = frame.geom_to_local(np.array([r.geometry for r in warning], dtype=object))
        i, _ = shapely.STRtree(wa).query(segs, predicate="intersects")
        warning_legs = {int(k) + 1 for k in i}
    return issues, legs, warning_legs
