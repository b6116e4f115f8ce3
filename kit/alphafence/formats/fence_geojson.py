"""The kit's fence GeoJSON: written by ``alphafence build``, read back by compile, upload,
monitor and route.

A FeatureCollection (RFC 7946, lon/lat) with one Feature per fence; the properties carry the
site, kind, method, margin and altitude band (see ``fence_properties``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence import __version__
from alphafence.errors import InputError
from alphafence.formats.features import check_coordinates
from alphafence.formats.jsonfile import read_json

KINDS = ("keep_out", "keep_in", "warning")


@dataclass
class FenceRecord:
    site_id: str
    kind: str
    geometry: object  # WGS84 Polygon / MultiPolygon
    margin_m: float = 0.0
    name: str | None = None
    category: str | None = None
    alt_min_m: float | None = None
    alt_max_m: float | None = None
    circle: tuple | None = None  # (lon, lat, radius_m)
    properties: dict = field(default_factory=dict)


def read_fences(path) -> list:
    doc = read_json(path)
    if (
        not isinstance(doc, dict)
        or doc.get("type") != "FeatureCollection"
        or not isinstance(doc.get("features"), list)
    ):
        raise InputError(path, "not a fence GeoJSON FeatureCollection")
    out = []
    for i, feat in enumerate(doc["features"]):
        props = feat.get("properties") if isinstance(feat, dict) else None
        if not isinstance(props, dict):
            raise InputError(path, "feature without properties", f"feature {i}")
        label = f"feature {i} ({props.get('site_id', '?')})"
        kind = props.get("kind")
        if kind not in KINDS:
            raise InputError(path, f"kind must be one of {', '.join(KINDS)}, not {kind!r}", label)
        try:
            geom = shapely.geometry.shape(feat.get("geometry"))
        except (
            ShapelyError,
            ValueError,
            TypeError,
            AttributeError,
            KeyError,
            IndexError,
        ) as exc:
            raise InputError(path, f"malformed geometry ({exc})", label) from None
        if geom.geom_type not in ("Polygon", "MultiPolygon"):
            raise InputError(
                path, f"a fence must be a Polygon or MultiPolygon, not {geom.geom_type}", label
            )
        circle = None
        if "radius_m" in props:
            c = props.get("center")
            r = props.get("radius_m")
            if not (isinstance(c, list) and len(c) == 2 and isinstance(r, (int, float)) and r > 0):
                raise InputError(
                    path, "circle fence needs center [lon, lat] and a positive radius_m", label
                )
            circle = (float(c[0]), float(c[1]), float(r))
        out.append(
            FenceRecord(
                site_id=str(props.get("site_id", f"fence/{i}")),
                kind=kind,
                geometry=geom,
                margin_m=float(props.get("margin_m") or 0.0),
                name=props.get("name"),
                category=props.get("category"),
                alt_min_m=props.get("alt_min_m"),
                alt_max_m=props.get("alt_max_m"),
                circle=circle,
                properties=props,
            )
        )
    if out:
        check_coordinates(
            path, np.array([f.geometry for f in out], dtype=object), lambda k: out[k].site_id
        )
    return out


# -- writing ----------------------------------------------------------------------------
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
