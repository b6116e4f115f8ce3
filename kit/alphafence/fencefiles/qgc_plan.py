"""QGroundControl .plan files (JSON, lat, lon order): the geoFence section written (version 2)
and read (versions 1 and 2, with its breach return point) as fence items, and missions written
from a route.

Missions are read as positions by ``alphafence.flights.mission``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from alphafence.errors import InputError
from alphafence.geo.coords import checked_position, latlon
from alphafence.mavlink import ids
from alphafence.mavlink.inclusions import UNION_WORDS, inclusion_count
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)
from alphafence.zones.jsonfile import read_json


def group_polygons(items):
    """Split a flat item list into polygons ``(command, [(lon, lat), ...])`` and circle items.

    Returns
    -------
    polygons : list of tuple
    circles : list of FenceItem

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> square = [FenceItem(5002, 3.0, 14.5, 35.9), FenceItem(5002, 3.0, 14.6, 35.9),
    ...           FenceItem(5002, 3.0, 14.5, 36.0)]
    >>> polygons, circles = group_polygons(square + [FenceItem(5004, 50.0, 14.7, 35.8)])
    >>> polygons
    [(5002, [(14.5, 35.9), (14.6, 35.9), (14.5, 36.0)])]
    >>> circles
    [FenceItem(command=5004, param1=50.0, lon=14.7, lat=35.8)]
    """
    polygons, circles, i = [], [], 0
    while i < len(items):
        it = items[i]
        if it.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            n = int(it.param1)
            polygons.append((it.command, [(p.lon, p.lat) for p in items[i : i + n]]))
            i += n
        else:
            if it.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
                circles.append(it)
            i += 1
    return polygons, circles


def plan_document(
    items, home_lonlat=None, mission_items=None, breach_return=None, sites=None,
    firmware=ids.MAV_AUTOPILOT_ARDUPILOTMEGA,
) -> dict:  # fmt: skip
    """A QGroundControl plan holding the fence ``items`` (and, optionally, a mission).

    Parameters
    ----------
    items : sequence of FenceItem
        The fence, as uploaded (polygons as consecutive vertices).
    home_lonlat : tuple, optional
        The planned home; by default the mean of the fence's positions.
    mission_items : list of dict, optional
        QGC SimpleItems (``mission_items``).
    breach_return : tuple, optional
        ``(lon, lat)`` of the fence's breach return point; by default the return point item
        among ``items`` (as a vehicle's fence holds it), if any.
    sites : list of list, optional
        Per polygon, then per circle: the sites it stands for (``{"id", "name"}`` each),
        written in its entry under ``alphafence`` (QGroundControl ignores the key).
    firmware : int
        The plan's ``firmwareType`` (MAV_AUTOPILOT: ArduPilot's 3, PX4's 12).

    Returns
    -------
    dict
        Ready for :func:`dumps`.

    Examples
    --------
    >>> doc = plan_document([FenceItem(5000, 0.0, 14.5, 35.9), FenceItem(5004, 50.0, 14.6, 35.8)])
    >>> doc["geoFence"]["breachReturn"], len(doc["geoFence"]["circles"])
    ([35.9, 14.5, 0], 1)
    """
    polygons, circles = group_polygons(items)
    if breach_return is None:
        breach_return = next(((i.lon, i.lat) for i in items if i.command == RETURN_POINT), None)
    if home_lonlat is None:
        pts = [p for _, poly in polygons for p in poly] + [(c.lon, c.lat) for c in circles]
        home_lonlat = tuple(np.mean(np.asarray(pts), axis=0)) if pts else (0.0, 0.0)
    home = latlon([home_lonlat])[0]
    fence = {}
    if breach_return is not None:
        lat, lon = latlon([breach_return])[0]
        fence["breachReturn"] = [lat, lon, 0]
    doc = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "AlphaFence",
        "geoFence": {
            "version": 2,
            "polygons": [
                {"inclusion": cmd == POLYGON_INCLUSION, "polygon": latlon(poly), "version": 1}
                for cmd, poly in polygons
            ],
            "circles": [
                {
                    "circle": {
                        "center": latlon([(c.lon, c.lat)])[0],
                        "radius": round(float(c.param1), 3),
                    },
                    "inclusion": c.command == CIRCLE_INCLUSION,
                    "version": 1,
                }
                for c in circles
            ],
            **fence,
        },
        "mission": {
            "version": 2,
            "firmwareType": int(firmware),
            "vehicleType": ids.MAV_TYPE_QUADROTOR,
            "cruiseSpeed": 10,
            "hoverSpeed": 5,
            "globalPlanAltitudeMode": 1,
            "plannedHomePosition": [home[0], home[1], 0],
            "items": list(mission_items or []),
        },
        "rallyPoints": {"version": 2, "points": []},
    }
    inclusions = inclusion_count(items)
    if inclusions > 1:  # ArduPilot intersects inclusions unless told otherwise
        doc["geoFence"]["alphafence"] = {
            "inclusion_areas": inclusions,
            "requires": f"{UNION_WORDS}: without it ArduPilot reads the areas as their "
            "intersection (alphafence upload sets it)",
        }
    entries = doc["geoFence"]["polygons"] + doc["geoFence"]["circles"]
    for entry, stands_for in zip(entries, sites or ()):
        if stands_for:
            entry["alphafence"] = {"sites": list(stands_for)}
    return doc


def dumps(doc) -> str:
    """The plan as indented JSON text."""
    return json.dumps(doc, indent=2) + "\n"


def _latlon_pair(path, where, pair):
    if not (
        isinstance(pair, list)
        and len(pair) >= 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair[:2])
    ):
        raise InputError(path, f"expected [lat, lon], got {pair!r}", where)
    return checked_position(path, where, float(pair[0]), float(pair[1]))


@dataclass(frozen=True)
class PlanFence:
    """The geoFence section of a QGroundControl plan.

    Attributes
    ----------
    items : list of FenceItem
        Its polygons (consecutive vertices), then its circles.
    return_point : tuple or None
        ``(lon, lat)`` of its ``breachReturn``.
    version : int
        The section's layout: 1 (one inclusion polygon, QGroundControl 3.2 and before) or 2.
    sites : list of list
        Per polygon, then per circle: the sites it stands for, ``{"id", "name"}`` each, as
        ``compile`` records them (``alphafence`` key of the entry; empty when none).
    """

    items: list
    return_point: tuple | None
    version: int
    sites: list = field(default_factory=list)

    @property
    def upload_items(self) -> list:
        """The items an upload sends: the return point first (as ``compile`` emits it), then
        the polygons and circles."""
        if self.return_point is None:
            return list(self.items)
        return [FenceItem(RETURN_POINT, 0.0, *self.return_point), *self.items]


def _version(path, fence):
    """The geoFence layout: the ``version`` QGroundControl wrote, or, without one, the layout
    its keys show (current QGroundControl ignores such a section: read, not dropped)."""
    v = fence.get("version")
    if v is None:
        return 1 if "polygon" in fence else 2
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v not in (1, 2):
        raise InputError(path, f"geoFence version {v!r}: known versions are 1 and 2")
    return int(v)


def _polygon(path, where, pts, inclusion):
    if not isinstance(pts, list) or len(pts) < 3:
        raise InputError(path, "a polygon needs at least 3 vertices", where)
    cmd = POLYGON_INCLUSION if inclusion else POLYGON_EXCLUSION
    return [FenceItem(cmd, float(len(pts)), *_latlon_pair(path, where, p)) for p in pts]


def read_plan_geofence(path) -> PlanFence:
    """The geoFence of a QGroundControl plan, in either layout QGroundControl has written.

    Version 2 (``GeoFenceController`` since QGroundControl 3.3): ``polygons`` and ``circles``,
    each with ``inclusion``. Version 1 (QGroundControl 3.2, and a section without a version
    that has its key): one ``polygon`` of ``[lat, lon]`` vertices, which ArduPilot and PX4
    fenced as an inclusion. Both may carry ``breachReturn``, ``[lat, lon]`` or
    ``[lat, lon, alt]``.

    Raises
    ------
    InputError
        One line naming the polygon, circle or key that is malformed, or an unknown version.
    """
    doc = read_json(path)
    fence = doc.get("geoFence") if isinstance(doc, dict) else None
    if not isinstance(fence, dict):
        raise InputError(path, "no geoFence section (not a QGroundControl plan?)")
    version = _version(path, fence)
    items = []
    if version == 1:
        pts = fence.get("polygon", [])
        if pts:
            items += _polygon(path, "geoFence polygon", pts, inclusion=True)
    else:
        polygons, circles = fence.get("polygons", []), fence.get("circles", [])
        for key, value in (("polygons", polygons), ("circles", circles)):
            if not isinstance(value, list):
                raise InputError(path, f"geoFence {key} must be a list, not {value!r}")
        for k, poly in enumerate(polygons):
            where = f"geoFence polygon {k}"
            if not isinstance(poly, dict):
                raise InputError(path, "a polygon must be an object", where)
            items += _polygon(path, where, poly.get("polygon"), bool(poly.get("inclusion")))
        for k, circ in enumerate(circles):
            items.append(_circle(path, f"geoFence circle {k}", circ))
    ret = None
    if fence.get("breachReturn") is not None:
        ret = _latlon_pair(path, "geoFence breachReturn", fence["breachReturn"])
    entries = [] if version == 1 else [*fence.get("polygons", []), *fence.get("circles", [])]
    return PlanFence(items, ret, version, [_sites(e) for e in entries])


def _sites(entry) -> list:
    """The sites a plan's polygon or circle stands for, as ``compile`` wrote them (its
    ``alphafence`` key; anything else there is not ours: none)."""
    own = entry.get("alphafence") if isinstance(entry, dict) else None
    sites = own.get("sites") if isinstance(own, dict) else None
    if not isinstance(sites, list):
        return []
    return [
        {"id": str(x["id"]), "name": x.get("name") if isinstance(x.get("name"), str) else None}
        for x in sites
        if isinstance(x, dict) and isinstance(x.get("id"), str)
    ]


def _circle(path, where, circ):
    c = circ.get("circle") if isinstance(circ, dict) else None
    if not isinstance(c, dict):
        raise InputError(path, "circle entry without 'circle'", where)
    lon, lat = _latlon_pair(path, where, c.get("center"))
    r = c.get("radius")
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) or r <= 0:
        raise InputError(path, f"radius must be a positive number, not {r!r}", where)
    cmd = CIRCLE_INCLUSION if circ.get("inclusion") else CIRCLE_EXCLUSION
    return FenceItem(cmd, float(r), lon, lat)


def read_plan_fence(path):
    """The polygons and circles of a QGroundControl plan's geoFence as FenceItems (polygons,
    then circles; the breach return point is :func:`read_plan_geofence`'s).

    Raises a one-line InputError naming the polygon or circle that is malformed.
    """
    return read_plan_geofence(path).items


# -- missions ---------------------------------------------------------------------------
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
    """QGC SimpleItems flying a path: takeoff at the first position, a waypoint at every later
    one, RTL.

    Positions use frame 3 (altitude relative to home); RTL has no position (frame 2, as
    QGroundControl writes it). RTL flies straight home, so with ``fly_back`` the mission first
    flies the path back to its start and RTL only lands there.

    Parameters
    ----------
    path_lonlat : array_like, shape (n, 2)
        The path, (lon, lat).
    alt : float
        Altitude above home, metres.
    fly_back : bool
        Fly the path back before RTL.

    Returns
    -------
    list of dict

    Examples
    --------
    >>> items = mission_items([(14.5, 35.9), (14.6, 35.95)], 30)
    >>> [it["command"] for it in items]  # takeoff, waypoint, waypoint back, RTL
    [22, 16, 16, 20]
    >>> items[1]["params"]
    [0, 0, 0, None, 35.95, 14.6, 30.0]
    """
    pts = np.asarray(path_lonlat, float).reshape(-1, 2)
    if fly_back and len(pts) > 1:
        pts = np.concatenate([pts, pts[-2::-1]])
    rel = ids.MAV_FRAME_GLOBAL_RELATIVE_ALT
    items = [_simple(1, ids.MAV_CMD_NAV_TAKEOFF, rel, pts[0], alt)]
    for p in pts[1:]:
        items.append(_simple(len(items) + 1, ids.MAV_CMD_NAV_WAYPOINT, rel, p, alt))
    items.append(
        _simple(len(items) + 1, ids.MAV_CMD_NAV_RETURN_TO_LAUNCH, ids.MAV_FRAME_MISSION, None, 0)
    )
    return items
