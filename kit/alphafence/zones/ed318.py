"""ED-318 UAS geographical zones: a GeoJSON FeatureCollection whose geometries carry a
vertical ``layer``. A zone's ``type`` is its restriction (``REQ_AUTHORIZATION`` spelt as
ED-269 spells it), its ``limitedApplicability`` when it is in force; each geometry becomes one
volume. Read by :func:`alphafence.zones.ed269.read_ed269_doc`."""

from __future__ import annotations

from alphafence.errors import InputError
from alphafence.zones import ed_fields as ed

_ED318_MARKS = ("zoneAuthority", "variant", "limitedApplicability", "UASZone", "verticalLayer")


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
        return ed.circle(path, label, geom.get("coordinates"), extent.get("radius"), 1.0)
    if gtype in ("Polygon", "MultiPolygon"):
        return ed.shape(path, label, gtype, geom.get("coordinates")), {}
    raise InputError(
        path,
        f"unsupported ED-318 geometry type {gtype!r} "
        "(zones are Polygon, MultiPolygon or Point with a Circle extent)",
        label,
    )


def ed318_zone(path, i, feat):
    """[(geometry, tags, source, lower, upper, properties)] per geometry of ED-318 zone
    ``i`` (a Feature), as :func:`alphafence.zones.ed269.read_ed269_doc` reads them.

    Raises
    ------
    InputError
        A one-line message naming the zone (or geometry) that is malformed.
    """
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
    reasons = ed.reasons(props.get("reasons", props.get("reason")))
    tags = ed.tags(restriction, reasons, _text(props.get("name")))
    geom = feat.get("geometry")
    parts = [geom]
    if isinstance(geom, dict) and geom.get("type") == "GeometryCollection":
        parts = geom.get("geometries")
    if not isinstance(parts, list) or not parts:
        raise InputError(path, "GeometryCollection needs geometries", label)
    out = []
    for j, part in enumerate(parts):
        elabel = label if len(parts) == 1 else f"{label} geometry {j}"
        if not isinstance(part, dict):
            raise InputError(path, "geometry must be an object", elabel)
        layer = part.get("layer", props.get("verticalLayer")) or {}
        if not isinstance(layer, dict):
            raise InputError(path, "layer must be an object", elabel)
        units = ed.unit(path, elabel, layer.get("uom", "m"), "layer uom")
        lower = ed.limit(path, elabel, layer, "lower", units)
        upper = ed.limit(path, elabel, layer, "upper", units)
        ed.band(path, elabel, lower, upper, ("lower", "upper"))
        shape, extra = _ed318_shape(path, elabel, part)
        refs = layer.get("lowerReference"), layer.get("upperReference")
        what = {"restriction": restriction, "reason": reasons,
                "applicability": props.get("limitedApplicability")}  # fmt: skip
        out.append(ed.volume(shape, tags, ident, j, len(parts), (lower, upper), what, refs, extra))
    return out
