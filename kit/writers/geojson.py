"""Fences as a GeoJSON FeatureCollection (RFC 7946, lon/lat), one Feature per fence."""

from __future__ import annotations

import json

import shapely

from kit import __version__

DECIMALS = 8  # 1e-8 degrees is about 1 mm; fences carry 0.1 m of slack for it


def fence_properties(f) -> dict:
    props = {
        "site_id": f.site_id,
        "name": f.name,
        "category": f.category,
        "kind": f.kind,
        "method": f.method,
        "margin_m": round(f.margin_m, 3),
        "alt_min_m": f.alt_min_m,
        "alt_max_m": f.alt_max_m,
        "vertices": f.vertices,
        "area_m2": round(f.area_m2, 1),
        "sources": list(f.sources),
    }
    if f.alpha_m is not None:
        props["alpha_m"] = round(f.alpha_m, 3) if f.alpha_m != float("inf") else None
    if f.circle is not None:
        lon, lat, r = f.circle_wgs84
        props["center"] = [round(lon, 9), round(lat, 9)]
        props["radius_m"] = round(r, 3)
    if f.repaired:
        props["repaired"] = True
    if f.properties:
        props["zone"] = f.properties
    return props


def fences_geojson(fences, meta: dict | None = None) -> dict:
    features = []
    for f in fences:
        gj = json.loads(shapely.to_geojson(f.geometry))
        gj["coordinates"] = _round(gj["coordinates"])
        features.append({"type": "Feature", "properties": fence_properties(f), "geometry": gj})
    doc = {"type": "FeatureCollection", "generator": f"alphafence {__version__}"}
    if meta:
        doc["alphafence"] = meta
    doc["features"] = features
    return doc


def _round(c):
    if isinstance(c, list) and c and isinstance(c[0], (int, float)):
        return [round(v, DECIMALS) for v in c]
    return [_round(x) for x in c]


def dumps(doc) -> str:
    return json.dumps(doc, separators=(",", ":"), ensure_ascii=False) + "\n"
