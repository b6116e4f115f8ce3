"""QGroundControl .plan files with a version-2 geoFence section (lat, lon order)."""

from __future__ import annotations

import json

import numpy as np

from kit.coords import latlon
from kit.writers.mavlink_items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
)

FIRMWARE_ARDUPILOT = 3
VEHICLE_MULTIROTOR = 2


def group_polygons(items):
    """Split a flat item list into polygons (command, [(lon, lat)...]) and circles."""
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


def plan_document(items, home_lonlat=None, mission_items=None, breach_return=None) -> dict:
    polygons, circles = group_polygons(items)
    if home_lonlat is None:
        pts = [p for _, poly in polygons for p in poly] + [(c.lon, c.lat) for c in circles]
        home_lonlat = tuple(np.mean(np.asarray(pts), axis=0)) if pts else (0.0, 0.0)
    home = latlon([home_lonlat])[0]
    fence = {}
    if breach_return is not None:
        lat, lon = latlon([breach_return])[0]
        fence["breachReturn"] = [lat, lon, 0]
    return {
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
            "firmwareType": FIRMWARE_ARDUPILOT,
            "vehicleType": VEHICLE_MULTIROTOR,
            "cruiseSpeed": 10,
            "hoverSpeed": 5,
            "globalPlanAltitudeMode": 1,
            "plannedHomePosition": [home[0], home[1], 0],
            "items": list(mission_items or []),
        },
        "rallyPoints": {"version": 2, "points": []},
    }


def dumps(doc) -> str:
    return json.dumps(doc, indent=2) + "\n"
