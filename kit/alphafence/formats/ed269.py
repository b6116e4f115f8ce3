"""EUROCAE ED-269 UAS geographical zones (``UASZoneVersion`` JSON, lon/lat), and their
successor ED-318 (a GeoJSON FeatureCollection whose geometries carry a vertical ``layer``).

ED-269 zones come as ``{"features": [...]}`` (InterUSS's ED269Schema), as
``{"UASZoneList": [...]}`` (the file layout InterUSS's checker and national exports use) or as
a bare list. Each zone becomes one feature per geometry entry (ED-318: per geometry), with
pseudo-tags the rules match on (``ed269:restriction``, ``ed269:reason``, ``name``), altitude
limits converted to metres (their references kept), and restriction and applicability kept as
properties. ED-318's zone ``type`` is the restriction (``REQ_AUTHORIZATION`` spelt as ED-269
spells it), its ``limitedApplicability`` the applicability. Circles are built in metres.
"""

from __future__ import annotations

import json
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
_ED318_MARKS = ("zoneAuthority", "variant", "limitedApplicability", "UASZone", "verticalLayer")
_SHAPE_ERRORS = (ValueError, TypeError, IndexError, KeyError, AttributeError, OverflowError)


def _zone_list(doc):
    """The ED-269 zone list of a document, or None."""
    if isinstance(doc, list):
        return doc
    if not isinstance(doc, dict):
        return None
    for key in ("features", "UASZoneList"):
        if isinstance(doc.get(key), list):
            return doc[key]
    return None


def looks_like_ed318(doc) -> bool:
    """Whether a parsed JSON document is an ED-318 FeatureCollection: a feature whose
    properties name a zone authority, variant or limited applicability, or whose geometry
    carries a vertical ``layer``.

    Examples
    --------
    >>> looks_like_ed318({"type": "FeatureCollection", "features": [
    ...     {"type": "Feature", "properties": {"identifier": "A1", "type": "PROHIBITED",
    ...      "zoneAuthority": [{"purpose": "INFORMATION"}]}, "geometry": None}]})
    True
    >>> looks_like_ed318({"type": "FeatureCollection", "features": []})
    False
    """
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        return False
    feats = doc.get("features")
    if not isinstance(feats, list):
        return False
    for feat in feats:
        if not isinstance(feat, dict):
            continue
        props, geom = feat.get("properties"), feat.get("geometry")
        if isinstance(props, dict) and any(k in props for k in _ED318_MARKS):
            return True
        if isinstance(geom, dict) and "layer" in geom:
            return True
    return False


def looks_like_ed269(doc) -> bool:
    """Whether a parsed JSON document is ED-269 (zones with a ``restriction`` or a list of
    geometries, or a ``UASZoneList``) or ED-318, rather than a plain GeoJSON FeatureCollection.

    Examples
    --------
    >>> looks_like_ed269({"features": [{"restriction": "PROHIBITED"}]})
    True
    >>> looks_like_ed269({"formatVersion": "1.0", "UASZoneList": []})
    True
    >>> looks_like_ed269({"type": "FeatureCollection", "features": []})
    False
    """
    if isinstance(doc, dict):
        if isinstance(doc.get("UASZoneList"), list):
            return True
        if doc.get("type") == "FeatureCollection":
            return looks_like_ed318(doc)
    feats = _zone_list(doc)
    if not feats:
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


def _number(value):
    """A finite float from a number or a numeric string (``"0"``), else None."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        return None
    try:
        value = float(value.strip() if isinstance(value, str) else value)
    except (ValueError, OverflowError):  # "ten"; an integer beyond any float
        return None
    return value if math.isfinite(value) else None


def _limit(path, label, geom, key, units):
    value = geom.get(key)
    if value is None:
        return None
    number = _number(value)
    if number is None:
        raise InputError(path, f"{key} must be a number, not {value!r}", label)
    return number * units


def _unit(path, label, value, key):
    unit = value.upper() if isinstance(value, str) else None  # a list is no unit (nor a key)
    if unit not in _UNITS:
        raise InputError(path, f"{key} must be M or FT, not {value!r}", label)
    return _UNITS[unit]


def _band(path, label, lower, upper, keys=("lowerLimit", "upperLimit")):
    if lower is not None and upper is not None and upper <= lower:
        raise InputError(path, f"{keys[1]} {upper} m is not above {keys[0]} {lower} m", label)


def _circle(path, label, center, radius, units):
    if (
        not isinstance(center, list)
        or len(center) != 2
        or not all(isinstance(c, (int, float)) and _number(c) is not None for c in center)
        or not valid_lonlat(*center)
    ):
        raise InputError(path, f"Circle center must be [lon, lat] in range, not {center!r}", label)
    r = _number(radius)
    if r is None or not r > 0:
        raise InputError(path, f"Circle radius must be a positive number, not {radius!r}", label)
    radius_m = r * units
    return circle_polygon(center[0], center[1], radius_m), {
        "circle": [center[0], center[1], radius_m]
    }


def _shape(path, label, gtype, coordinates):
    try:
        return shapely.geometry.shape({"type": gtype, "coordinates": coordinates})
    except (*_SHAPE_ERRORS, ShapelyError) as exc:
        raise InputError(path, f"malformed {gtype} ({exc})", label) from None


def _projection(path, label, proj, units=1.0):
    if not isinstance(proj, dict):
        raise InputError(path, "horizontalProjection must be an object", label)
    ptype = proj.get("type")
    if ptype == "Circle":  # uomDimensions applies to the radius too
        return _circle(path, label, proj.get("center"), proj.get("radius"), units)
    if ptype in ("Polygon", "MultiPolygon"):
        return _shape(path, label, ptype, proj.get("coordinates")), {}
    raise InputError(path, f"unknown horizontalProjection type {ptype!r}", label)


def _reasons(value):
    return [] if not value else value if isinstance(value, list) else [value]


def _tags(restriction, reasons, name):
    tags = {"ed269:restriction": restriction}
    if reasons:
        tags["ed269:reason"] = ";".join(str(r) for r in reasons)
    if name:
        tags["name"] = str(name)
    return tags


def _ed269_volumes(path, feats):
    """(geometry, tags, source, lower, upper, properties) per geometry entry of each zone."""
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
        reasons = _reasons(zone.get("reason"))
        tags = _tags(restriction, reasons, zone.get("name"))
        for j, entry in enumerate(entries):
            elabel = label if len(entries) == 1 else f"{label} geometry {j}"
            if not isinstance(entry, dict):
                raise InputError(path, "geometry entry must be an object", elabel)
            units = _unit(path, elabel, entry.get("uomDimensions", "M"), "uomDimensions")
            lower = _limit(path, elabel, entry, "lowerLimit", units)
            upper = _limit(path, elabel, entry, "upperLimit", units)
            _band(path, elabel, lower, upper)
            geom, extra = _projection(path, elabel, entry.get("horizontalProjection"), units)
            props = {
                "restriction": restriction,
                "reason": reasons,
                "applicability": zone.get("applicability"),
                "lower_reference": entry.get("lowerVerticalReference"),
                "upper_reference": entry.get("upperVerticalReference"),
                **extra,
            }
            source = str(ident) if len(entries) == 1 else f"{ident}#{j}"
            yield geom, dict(tags), source, lower, upper, props


def _text(value):
    """An ED-318 text (a string, ``{"text": ...}``, or a list of them, the first taken)."""
    if isinstance(value, list):
        value = value[0] if value else None
    if isinstance(value, dict):
        value = value.get("text")
    return value if isinstance(value, str) and value else None


def _ed318_shape(path, label, geom):
    gtype = geom.get("type")
    if gtype == "Point":
        extent = geom.get("extent")
        if not isinstance(extent, dict) or extent.get("subType") != "Circle":
            raise InputError(path, "a Point zone needs a Circle extent (subType, radius)", label)
        return _circle(path, label, geom.get("coordinates"), extent.get("radius"), 1.0)
    if gtype in ("Polygon", "MultiPolygon"):
        return _shape(path, label, gtype, geom.get("coordinates")), {}
    raise InputError(
        path,
        f"unsupported ED-318 geometry type {gtype!r} "
        "(zones are Polygon, MultiPolygon or Point with a Circle extent)",
        label,
    )


def _ed318_volumes(path, feats):
    """(geometry, tags, source, lower, upper, properties) per geometry of each ED-318 zone."""
    for i, feat in enumerate(feats):
        if not isinstance(feat, dict) or not isinstance(feat.get("properties"), dict):
            raise InputError(path, "zone must be a Feature with properties", f"feature {i}")
        props = feat["properties"]
        if isinstance(props.get("UASZone"), dict):  # the zone nested, as some writers do
            props = {**props, **props["UASZone"]}
        ident = props.get("identifier") or f"feature/{i}"
        label = f"zone {ident}"
        ztype = props.get("type")
        if not isinstance(ztype, str) or not ztype:
            raise InputError(path, "missing zone type", label)
        restriction = ztype.upper().replace("REQ_AUTHORIZATION", "REQ_AUTHORISATION")
        reasons = _reasons(props.get("reasons", props.get("reason")))
        tags = _tags(restriction, reasons, _text(props.get("name")))
        geom = feat.get("geometry")
        parts = [geom]
        if isinstance(geom, dict) and geom.get("type") == "GeometryCollection":
            parts = geom.get("geometries")
        if not isinstance(parts, list) or not parts:
            raise InputError(path, "GeometryCollection needs geometries", label)
        for j, part in enumerate(parts):
            elabel = label if len(parts) == 1 else f"{label} geometry {j}"
            if not isinstance(part, dict):
                raise InputError(path, "geometry must be an object", elabel)
            layer = part.get("layer", props.get("verticalLayer")) or {}
            if not isinstance(layer, dict):
                raise InputError(path, "layer must be an object", elabel)
            units = _unit(path, elabel, layer.get("uom", "m"), "layer uom")
            lower = _limit(path, elabel, layer, "lower", units)
            upper = _limit(path, elabel, layer, "upper", units)
            _band(path, elabel, lower, upper, ("lower", "upper"))
            shape, extra = _ed318_shape(path, elabel, part)
            zprops = {
                "restriction": restriction,
                "reason": reasons,
                "applicability": props.get("limitedApplicability"),
                "lower_reference": layer.get("lowerReference"),
                "upper_reference": layer.get("upperReference"),
                **extra,
            }
            source = str(ident) if len(parts) == 1 else f"{ident}#{j}"
            yield shape, dict(tags), source, lower, upper, zprops


def zone_class(properties) -> tuple:
    """What a zone must share with another, beyond its rule and altitude band, for the two to
    share one fence: its restriction, when it is in force, and its vertical references.

    Permanent zones are alike however they say so (no applicability, or a ``permanent: YES``
    period); other applicabilities are compared as canonical JSON. Features that are no
    ED-269/ED-318 zone (no properties) give ``()``.

    Examples
    --------
    >>> zone_class({})
    ()
    >>> zone_class({"restriction": "PROHIBITED", "applicability": [{"permanent": "YES"}],
    ...             "lower_reference": "AGL", "upper_reference": "AMSL"})
    ('"PROHIBITED"', 'permanent', '"AGL"', '"AMSL"')
    """
    if not properties:
        return ()
    when = properties.get("applicability")
    entries = when if isinstance(when, list) else [when]
    if not when or any(
        isinstance(e, dict) and str(e.get("permanent", "")).upper() == "YES" for e in entries
    ):
        when = "permanent"  # in force at any time, as the monitor reads it
    else:
        when = json.dumps(when, sort_keys=True, default=str)
    return (
        json.dumps(properties.get("restriction"), default=str),
        when,
        json.dumps(properties.get("lower_reference"), default=str),
        json.dumps(properties.get("upper_reference"), default=str),
    )


def read_ed269_doc(path, doc, rules, repaired, skipped):
    """The restricted features of a parsed ED-269 (or ED-318) document.

    Each geometry entry of each zone becomes one Feature, its tags ``ed269:restriction``,
    ``ed269:reason`` and ``name`` matched against ``rules``; altitude limits are converted to
    metres (a rule's limits stand in for missing ones). Limits given as numeric strings
    (``"120"``) are read as numbers.

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
    if looks_like_ed318(doc):
        volumes, what = list(_ed318_volumes(path, doc["features"])), "ED-318"
    else:
        feats = _zone_list(doc)
        if feats is None:
            raise InputError(path, "ED-269 document needs a 'features' or 'UASZoneList' list")
        volumes, what = list(_ed269_volumes(path, feats)), "ED-269"
    if not volumes:
        return []
    geoms = np.array([v[0] for v in volumes], dtype=object)
    check_coordinates(path, geoms, lambda k: f"zone {volumes[k][2]}")
    geoms = flag_invalid(geoms, [v[2] for v in volumes], repaired)
    out = []
    for g, (_, tags, source, lower, upper, props) in zip(geoms, volumes):
        rule = rules.match(tags.get, "area")
        if rule is None:
            skipped[f"{what} zone with restriction {tags['ed269:restriction']} (no rule)"] += 1
            continue
        alt_min = lower if lower is not None else rule.alt_min_m
        alt_max = upper if upper is not None else rule.alt_max_m
        out.append(Feature(g, tags, source, str(path), rule, alt_min, alt_max, props))
    return out
