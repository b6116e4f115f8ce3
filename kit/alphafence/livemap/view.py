"""What the live map shows, as JSON messages: the vehicle with its predicted path and stopping
point, the full-resolution fences near it, the fence it holds, other aircraft with their
protection volumes. Built by each page's sender task (:mod:`alphafence.livemap.observer`), never
by the monitor's callbacks; distances on the ellipsoid (pyproj), never in degrees.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pyproj
import shapely

from alphafence.awareness.predict import dynamic_radius, stopping_distance

GEOD = pyproj.Geod(ellps="WGS84")
MIN_HEADING_SPEED_MPS = 0.3  # slower than this, the velocity says nothing of a heading
MAX_NEAR_FENCES = 5000  # at most this many fences near the vehicle are sent (nearest kept)
LOOKAHEAD_MIN_M = 50.0  # the engine looks at least this far ahead (monitor.engine)
PROPERTIES = ("site_id", "name", "category", "kind", "margin_m", "alt_min_m", "alt_max_m")
UNKNOWN = "UNKNOWN"  # the level before a live source alone has answered: never CLEAR


def _ahead(lon, lat, azimuth, metres):
    """The point ``metres`` along ``azimuth`` (degrees from north) from lon, lat."""
    lon2, lat2, _ = GEOD.fwd(lon, lat, azimuth, metres)
    return [round(lat2, 7), round(lon2, 7)]


def vehicle_message(step, options, checks: int) -> dict:
    """The vehicle as the engine last stepped it: where, heading, speed, level, and what the
    engine predicted from it: the track it looked along (``path``: ``[lat, lon]`` now and at
    the look-ahead, ``lookahead_m``) and where braking now would stop it (``stop``,
    ``stopping_m``).

    Parameters
    ----------
    step : Step
        The engine's latest step.
    options : MonitorOptions
        The horizon and the braking model.
    checks : int
        The engine's positions checked so far.

    Returns
    -------
    dict
    """
    s = step.sample
    speed = math.hypot(s.vn, s.ve) if math.isfinite(s.vn) and math.isfinite(s.ve) else 0.0
    heading = (
        math.degrees(math.atan2(s.ve, s.vn)) % 360.0 if speed >= MIN_HEADING_SPEED_MPS else None
    )
    lookahead = max(LOOKAHEAD_MIN_M, speed * options.horizon_s)
    stopping = stopping_distance(speed, options.braking)
    here = [round(s.lat, 7), round(s.lon, 7)]
    moving = heading is not None
    return {
        "type": "vehicle",
        "t": round(s.t, 3),
        "lat": here[0],
        "lon": here[1],
        "alt_m": _num(s.alt_m),
        "speed_mps": round(speed, 2),
        "heading_deg": None if heading is None else round(heading, 1),
        "mode": s.mode,
        "armed": s.armed,
        "level": step.level.name if getattr(step, "known", True) else UNKNOWN,
        "checked": step.checked,
        "checks": checks,
        "lookahead_m": round(lookahead, 1),
        "stopping_m": round(stopping, 1),
        "path": [here, _ahead(s.lon, s.lat, heading, lookahead)] if moving else [here],
        "stop": _ahead(s.lon, s.lat, heading, stopping) if moving else here,
    }


def _num(v, digits=2):
    return round(v, digits) if isinstance(v, (int, float)) and math.isfinite(v) else None


class NearFences:
    """The full-resolution fences indexed in lon/lat for "which are near this point", the
    answer as a GeoJSON FeatureCollection's text. Its own index (the FenceSet's may be rebuilt
    by the monitor), so it can be asked from a worker thread.

    Parameters
    ----------
    records : list of FenceRecord
        The fences (WGS84).
    """

    def __init__(self, records):
        self.records = list(records)
        self.geoms = np.array([r.geometry for r in self.records], dtype=object)
        self.tree = shapely.STRtree(self.geoms)

    def around(self, lon: float, lat: float, radius_m: float) -> str:
        """The fences within ``radius_m`` of lon, lat (the box around that circle; at most
        :data:`MAX_NEAR_FENCES`, the nearest), as the text of a message ``{"type": "fences",
        "center": [lat, lon], "radius_m", "total", "sent", "geojson"}``."""
        _, south, _ = GEOD.fwd(lon, lat, 180.0, radius_m)
        _, north, _ = GEOD.fwd(lon, lat, 0.0, radius_m)
        west, _, _ = GEOD.fwd(lon, lat, 270.0, radius_m)
        east, _, _ = GEOD.fwd(lon, lat, 90.0, radius_m)
        idx = self.tree.query(shapely.box(west, south, east, north))
        total = len(idx)
        if total > MAX_NEAR_FENCES:
            here = shapely.Point(lon, lat)
            idx = idx[np.argsort(shapely.distance(self.geoms[idx], here))[:MAX_NEAR_FENCES]]
        idx = np.sort(idx)
        shapes = shapely.to_geojson(self.geoms[idx]) if len(idx) else []
        features = ",".join(
            f'{{"type":"Feature","properties":{json.dumps(self._properties(k))},"geometry":{g}}}'
            for k, g in zip(idx.tolist(), shapes)
        )
        head = json.dumps(
            {
                "type": "fences",
                "center": [round(lat, 7), round(lon, 7)],
                "radius_m": radius_m,
                "total": total,
                "sent": len(idx),
            }
        )
        return f'{head[:-1]},"geojson":{{"type":"FeatureCollection","features":[{features}]}}}}'

    def _properties(self, k) -> dict:
        r = self.records[k]
        props = {p: getattr(r, p) for p in PROPERTIES if getattr(r, p) is not None}
        if r.circle is not None:
            props["center"], props["radius_m"] = list(r.circle[:2]), r.circle[2]
        for key, value in (r.properties or {}).items():
            props.setdefault(key, value)
        return props


def onboard_message(layer, cause=None) -> dict:
    """The fence the vehicle holds (the engine's onboard layer) as GeoJSON: each polygon
    and circle (a circle as its centre with ``radius_m``), inclusion or exclusion, named as
    the monitor names it; no layer: no features."""
    features = []
    for f in [] if layer is None else layer.fences:
        props = {"name": f.name, "kind": f.kind, "shape": f.shape, "items": f.items}
        if f.shape == "circle":
            lon, lat = f.lonlat[0]
            props["radius_m"] = f.radius_m
            geometry = {"type": "Point", "coordinates": [lon, lat]}
        else:
            ring = [list(p) for p in f.lonlat]
            geometry = {"type": "Polygon", "coordinates": [ring + ring[:1]]}
        features.append({"type": "Feature", "properties": props, "geometry": geometry})
    return {
        "type": "onboard",
        "cause": cause,
        "items": None if layer is None else layer.items,
        "geojson": {"type": "FeatureCollection", "features": features},
    }


def traffic_message(aircraft: dict, step, traffic_options, conflicts) -> dict:
    """Other aircraft, each dead-reckoned to the vehicle's latest step from its last report,
    with its protection volume: the cylinder the engine judges it by (``radius_m``, grown
    by how fast it and the vehicle close; ``half_height_m``) and whether it is in conflict.

    Parameters
    ----------
    aircraft : dict
        ``{key: (t, report)}``: each one's latest report (``Engine.aircraft``'s keywords).
    step : Step or None
        The vehicle's latest step (None: not known yet: volumes at their base radius).
    traffic_options : TrafficOptions
    conflicts : set
        The keys of the aircraft in conflict now.

    Returns
    -------
    dict
    """
    o = traffic_options
    out = []
    now = max((t for t, _ in aircraft.values()), default=0.0)
    s = None if step is None else step.sample
    if s is not None:
        now = max(now, s.t)
    for key, (t, r) in aircraft.items():
        age = now - t
        if age > o.stale_s:
            continue
        ve, vn = float(r.get("ve") or 0.0), float(r.get("vn") or 0.0)
        speed = math.hypot(ve, vn)
        az = math.degrees(math.atan2(ve, vn))
        lon, lat, _ = GEOD.fwd(r["lon"], r["lat"], az, speed * max(age, 0.0))
        closing = 0.0
        if s is not None:
            az12, _, dist = GEOD.inv(s.lon, s.lat, lon, lat)
            if dist > 1e-6:
                ux, uy = math.sin(math.radians(az12)), math.cos(math.radians(az12))
                closing = -((ve - s.ve) * ux + (vn - s.vn) * uy)
        out.append(
            {
                "key": str(key),
                "callsign": r.get("callsign") or "",
                "lat": round(lat, 7),
                "lon": round(lon, 7),
                "alt_amsl_m": _num(r.get("alt_amsl_m")),
                "heading_deg": round(az % 360.0, 1) if speed >= MIN_HEADING_SPEED_MPS else None,
                "speed_mps": round(speed, 1),
                "radius_m": round(dynamic_radius(o.horizontal_m, closing, o.reaction_s), 1),
                "half_height_m": o.vertical_m,
                "conflict": str(key) in {str(c) for c in conflicts},
                "age_s": round(age, 1),
            }
        )
    return {"type": "traffic", "aircraft": out}
