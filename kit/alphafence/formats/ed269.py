"""EUROCAE ED-269 UAS geographical zones (``UASZoneVersion`` JSON, lon/lat).

Each zone becomes one feature per geometry entry, with pseudo-tags the rules match on
(``ed269:restriction``, ``ed269:reason``, ``name``), altitude limits converted to metres
(their references kept), and restriction and applicability kept as properties.
Circles are built in a local metric frame, never in degrees.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence.errors import InputError
from alphafence.formats.features import Feature, check_coordinates, flag_invalid
from alphafence.geo.coords import valid_lonlat
from alphafence.geo.frame import LocalFrame

_UNITS = {"M": 1.0, "FT": 0.3048}
_CIRCLE_SEGMENTS = 64


def looks_like_ed269(doc) -> bool:
    """Whether a parsed JSON document is ED-269 (zones with a ``restriction`` or a list of
    geometries) rather than a GeoJSON FeatureCollection.

    Examples
    --------
    >>> looks_like_ed269({"features": [{"restriction": "PROHIBITED"}]})
    True
    >>> looks_like_ed269({"type": "FeatureCollection", "features": []})
    False
    """
    feats = doc.get("features") if isinstance(doc, dict) else doc
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        return False
    if not isinstance(feats, list) or not feats:
        return False
    first = feats[0]
    return isinstance(first, dict) and (
        "restriction" in first or "geometry" in first and isinstance(first.get("geometry"), list)
    )


def circle_polygon(lon, lat, radius_m):
    """A WGS84 polygon that contains the circle (circumscribed, so never cuts into it).

    Parameters
    ----------
    lon, lat : float
        The centre, degrees.
    radius_m : float
        The radius, metres (the polygon is built in a local metric frame).

    Returns
    -------
    shapely.Polygon
        64 vertices.
    """
    frame = LocalFrame(lon, lat)
    r_out = radius_m / math.cos(math.pi / _CIRCLE_SEGMENTS)
    ang = (
        np.linspace(0.0, 2.0 * math.pi, _CIRCLE_SEGMENTS, endpoint=False)
        + math.pi / _CIRCLE_SEGMENTS
    )
    lons, lats = frame.to_wgs84(r_out * np.cos(ang), r_out * np.sin(ang))
    return shapely.Polygon(np.column_stack([lons, lats]))


def _limit(path, label, geom, key, units):
    value = geom.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(path, f"{key} must be a number, not {value!r}", label)
    return float(value) * units


def _projection(path, label, proj, units=1.0):
    if not isinstance(proj, dict):
        raise InputError(path, "horizontalProjection must be an object", label)
    ptype = proj.get("type")
    if ptype == "Circle":
        center = proj.get("center")
        radius = proj.get("radius")
        if (
            not isinstance(center, list)
            or len(center) != 2
            or not all(isinstance(c, (int, float)) for c in center)
            or not valid_lonlat(*center)
        ):
            raise InputError(
                path, f"Circle center must be [lon, lat] in range, not {center!r}", label
            )
        if (
            isinstance(radius, bool)
            or not isinstance(radius, (int, float))
            or not radius > 0
            or not math.isfinite(radius)
        ):
            raise InputError(
                path, f"Circle radius must be a positive number, not {radius!r}", label
            )
        radius_m = float(radius) * units  # uomDimensions applies to the radius too
        return circle_polygon(center[0], center[1], radius_m), {
            "circle": [center[0], center[1], radius_m]
        }
    if ptype in ("Polygon", "MultiPolygon"):
        try:
            geom = shapely.geometry.shape({"type": ptype, "coordinates": proj.get("coordinates")})
        except (ValueError, TypeError, IndexError, KeyError, AttributeError, ShapelyError) as exc:
            raise InputError(path, f"malformed {ptype} ({exc})", label) from None
        return geom, {}
    raise InputError(path, f"unknown horizontalProjection type {ptype!r}", label)


def read_ed269_doc(path, doc, rules, repaired, skipped):
    """The restricted features of a parsed ED-269 document.

    Each geometry entry of each zone becomes one Feature, its tags ``ed269:restriction``,
    ``ed269:reason`` and ``name`` matched against ``rules``; altitude limits are converted to
    metres (a rule's limits stand in for missing ones).

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    doc : dict or list
        The parsed JSON.
    rules : Rules
    repaired : list
        Sources of invalid polygons are appended (they are repaired later).
    skipped : collections.Counter
        Reasons for zones left out are counted.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        A one-line message naming the zone that is malformed.
    """
    feats = doc.get("features") if isinstance(doc, dict) else doc
    if not isinstance(feats, list):
        raise InputError(path, "ED-269 document needs a 'features' list")
    geoms, metas = [], []
    for i, zone in enumerate(feats):
        if not isinstance(zone, dict):
            raise InputError(path, "zone must be an object", f"zone {i}")
        ident = zone.get("identifier") or f"zone/{i}"
        label = f"zone {ident}"
        restriction = zone.get("restriction")
        if not isinstance(restriction, str):
            raise InputError(path, "missing restriction", label)
        entries = zone.get("geometry")
        if not isinstance(entries, list) or not entries:
            raise InputError(path, "geometry must be a non-empty list", label)
        reasons = zone.get("reason") or []
        if isinstance(reasons, str):
            reasons = [reasons]
        tags = {"ed269:restriction": restriction}
        if reasons:
            tags["ed269:reason"] = ";".join(str(r) for r in reasons)
        if zone.get("name"):
            tags["name"] = str(zone["name"])
        for j, entry in enumerate(entries):
            elabel = label if len(entries) == 1 else f"{label} geometry {j}"
            if not isinstance(entry, dict):
                raise InputError(path, "geometry entry must be an object", elabel)
            unit = entry.get("uomDimensions", "M")
            if unit not in _UNITS:
                raise InputError(path, f"uomDimensions must be M or FT, not {unit!r}", elabel)
            lower = _limit(path, elabel, entry, "lowerLimit", _UNITS[unit])
            upper = _limit(path, elabel, entry, "upperLimit", _UNITS[unit])
            if lower is not None and upper is not None and upper <= lower:
                raise InputError(
                    path, f"upperLimit {upper} m is not above lowerLimit {lower} m", elabel
                )
            geom, extra = _projection(path, elabel, entry.get("horizontalProjection"), _UNITS[unit])
            props = {
                "restriction": restriction,
                "reason": reasons,
                "applicability": zone.get("applicability"),
                "lower_reference": entry.get("lowerVerticalReference"),
                "upper_reference": entry.get("upperVerticalReference"),
                **extra,
            }
            source = str(ident) if len(entries) == 1 else f"{ident}#{j}"
            geoms.append(geom)
            metas.append((dict(tags), source, lower, upper, props))
    if not geoms:
        return []
    geoms = np.array(geoms, dtype=object)
    check_coordinates(path, geoms, lambda k: f"zone {metas[k][1]}")
    geoms = flag_invalid(geoms, [m[1] for m in metas], repaired)
    out = []
    for g, (tags, source, lower, upper, props) in zip(geoms, metas):
        rule = rules.match(tags.get, "area")
        if rule is None:
            skipped[f"ED-269 zone with restriction {tags['ed269:restriction']} (no rule)"] += 1
            continue
        alt_min = lower if lower is not None else rule.alt_min_m
        alt_max = upper if upper is not None else rule.alt_max_m
        out.append(Feature(g, tags, source, str(path), rule, alt_min, alt_max, props))
    return out
