"""Read back the fence GeoJSON that ``alphafence build`` writes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.errors import ShapelyError

from kit.errors import InputError
from kit.features import check_coordinates
from kit.readers import read_json

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
