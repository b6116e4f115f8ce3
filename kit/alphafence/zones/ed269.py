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

from alphafence.errors import InputError
from alphafence.zones import ed_fields as ed
from alphafence.zones.ed318 import ed318_zone, looks_like_ed318
from alphafence.zones.features import Feature, coordinate_faults, flag_invalid, settle_faults


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


def _ed269_zone(path, i, zone):
    """[(geometry, tags, source, lower, upper, properties)] per geometry entry of zone ``i``."""
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
    reasons = ed.reasons(zone.get("reason"))
    tags = ed.tags(restriction, reasons, zone.get("name"))
    out = []
    for j, entry in enumerate(entries):
        elabel = label if len(entries) == 1 else f"{label} geometry {j}"
        if not isinstance(entry, dict):
            raise InputError(path, "geometry entry must be an object", elabel)
        units = ed.unit(path, elabel, entry.get("uomDimensions", "M"), "uomDimensions")
        lower = ed.limit(path, elabel, entry, "lowerLimit", units)
        upper = ed.limit(path, elabel, entry, "upperLimit", units)
        ed.band(path, elabel, lower, upper)
        geom, extra = ed.projection(path, elabel, entry.get("horizontalProjection"), units)
        refs = entry.get("lowerVerticalReference"), entry.get("upperVerticalReference")
        what = {"restriction": restriction, "reason": reasons,
                "applicability": zone.get("applicability")}  # fmt: skip
        out.append(ed.volume(geom, tags, ident, j, len(entries), (lower, upper), what, refs, extra))
    return out


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


def read_ed269_doc(path, doc, rules, repaired, skipped, invalid=None):
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
    invalid : list, optional
        When given (``--skip-invalid``), malformed zones are left out, whole, and described
        here (:func:`~alphafence.zones.features.invalid_entries`); when None, they are
        raised.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        Every malformed zone at once: one, in a line naming it; several, one line each
        (:class:`~alphafence.errors.InputErrors`).
    """
    if looks_like_ed318(doc):
        zones, read_zone, what = doc["features"], ed318_zone, "ED-318"
    else:
        zones, read_zone, what = _zone_list(doc), _ed269_zone, "ED-269"
        if zones is None:
            raise InputError(path, "ED-269 document needs a 'features' or 'UASZoneList' list")
    volumes, faults = [], {}
    for i, zone in enumerate(zones):
        try:
            volumes.extend((i, *v) for v in read_zone(path, i, zone))
        except InputError as exc:  # every zone's fault, not only the first
            faults[i] = exc
    bad = coordinate_faults(path, [v[1] for v in volumes], lambda k: f"zone {volumes[k][3]}")
    for k in sorted(bad):
        faults.setdefault(volumes[k][0], bad[k])  # the zone's first fault
    settle_faults(path, [faults[i] for i in sorted(faults)], invalid)
    volumes = [v[1:] for v in volumes if v[0] not in faults]  # a malformed zone, whole
    if not volumes:
        return []
    geoms = flag_invalid([v[0] for v in volumes], [v[2] for v in volumes], repaired)
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
