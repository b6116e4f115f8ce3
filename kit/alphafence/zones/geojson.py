"""GeoJSON FeatureCollections (lon, lat), including the shape QGIS exports from OSM.

QGIS/GDAL exports carry one column per tag with nulls for absent tags, ids in
``osm_id`` / ``osm_way_id`` (and sometimes ``osm_type``), and the remaining tags as an
hstore string in ``other_tags`` (``"key"=>"value","k2"=>"v2"``).
"""

from __future__ import annotations

import re

import shapely
from shapely.errors import GeometryTypeError, ShapelyError

from alphafence.errors import InputError
from alphafence.zones.features import (
    Feature,
    coordinate_faults,
    flag_invalid,
    geomtype_of,
    settle_faults,
)

_HSTORE = re.compile(r'"((?:[^"\\]|\\.)*)"\s*=>\s*(?:"((?:[^"\\]|\\.)*)"|NULL)')
_ID_KEYS = ("osm_id", "osm_way_id", "osm_type", "fid", "id", "@id")


def parse_hstore(text: str) -> dict:
    """Tags from an hstore string (GDAL's ``other_tags``); NULL values are left out.

    Examples
    --------
    >>> parse_hstore('"amenity"=>"hospital","name"=>"St. \\\\"Luke\\\\"","x"=>NULL')
    {'amenity': 'hospital', 'name': 'St. "Luke"'}
    """
    out = {}
    for m in _HSTORE.finditer(text):
        if m.group(2) is not None:
            out[m.group(1).replace('\\"', '"')] = m.group(2).replace('\\"', '"')
    return out


def tags_of(props: dict) -> dict:
    """Tag columns with nulls dropped; other_tags expanded; values as strings.

    Examples
    --------
    >>> tags_of({"osm_id": "5", "amenity": "hospital", "building": None,
    ...          "other_tags": '"emergency"=>"yes"'})
    {'amenity': 'hospital', 'emergency': 'yes'}
    """
    tags = {}
    for key, value in props.items():
        if value is None or key in _ID_KEYS or key == "other_tags":
            continue
        if isinstance(value, bool):
            value = "yes" if value else "no"
        elif isinstance(value, (dict, list)):
            continue
        tags[key] = str(value)
    other = props.get("other_tags")
    if isinstance(other, str):
        for k, v in parse_hstore(other).items():
            tags.setdefault(k, v)
    return tags


def source_of(feature: dict, props: dict, gtype: str, index: int) -> str:
    """Where a feature came from, as ``"way/123"``: OSM ids (QGIS/GDAL columns), an ``@id``
    or ``id`` with a slash, the feature's id, or else its index.

    Examples
    --------
    >>> source_of({}, {"osm_way_id": "123"}, "area", 0)
    'way/123'
    >>> source_of({}, {"osm_id": "9"}, "point", 0)
    'node/9'
    >>> source_of({"id": 7}, {}, "area", 3), source_of({}, {}, "area", 3)
    ('feature/7', 'feature/3')
    """
    osm_type = props.get("osm_type")
    if props.get("osm_way_id") not in (None, ""):
        return f"way/{props['osm_way_id']}"
    if props.get("osm_id") not in (None, ""):
        if isinstance(osm_type, str) and osm_type:
            return f"{osm_type.lower()}/{props['osm_id']}"
        # GDAL's OSM driver: points are nodes, lines ways, multipolygons relations
        kind = {"point": "node", "line": "way", "area": "relation"}.get(gtype, "feature")
        return f"{kind}/{props['osm_id']}"
    for key in ("@id", "id"):
        if isinstance(props.get(key), str) and "/" in props[key]:
            return props[key]
    if feature.get("id") not in (None, ""):
        fid = feature["id"]
        return fid if isinstance(fid, str) and "/" in fid else f"feature/{fid}"
    return f"feature/{index}"


def read_geojson_doc(path, doc, rules, repaired, skipped, invalid=None):
    """The restricted features of a parsed GeoJSON FeatureCollection.

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    doc : dict
        The parsed JSON.
    rules : Rules
        Features no rule matches are left out.
    repaired : list
        Sources of invalid polygons are appended (they are repaired later).
    skipped : collections.Counter
        Reasons for features left out are counted.
    invalid : list, optional
        When given (``--skip-invalid``), malformed features are left out and described here
        (:func:`~alphafence.zones.features.invalid_entries`); when None, they are raised.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        Every malformed feature at once: one, in a line naming it; several, one line each
        (:class:`~alphafence.errors.InputErrors`).
    """
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise InputError(path, "not a GeoJSON FeatureCollection")
    raw = doc.get("features")
    if not isinstance(raw, list):
        raise InputError(path, "FeatureCollection has no 'features' list")
    return features_of(path, enumerate(raw), rules, repaired, skipped, invalid=invalid)


def features_of(path, numbered, rules, repaired, skipped, parsed=None, invalid=None, faults=None):
    """The restricted features among GeoJSON Feature objects.

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    numbered : iterable of (int, object)
        Each parsed Feature with its index in the file.
    rules, repaired, skipped
        As for :func:`read_geojson_doc`.
    parsed : sequence of shapely geometry or None, optional
        Each Feature's geometry as GEOS read it from the text (``shapely.from_geojson``, in
        one vectorised call), or None where it could not: those are read from the parsed
        object, which also gives their error message.
    invalid : list, optional
        As for :func:`read_geojson_doc`.
    faults : list, optional
        Where a reader of many batches gathers the faults (InputErrors) of every batch, to
        settle them at the file's end (:func:`~alphafence.zones.features.settle_faults`);
        when None, this batch's are settled here, with ``invalid``.

    Returns
    -------
    list of Feature
    """
    found, settle = [], faults is None
    faults = [] if faults is None else faults
    for k, (i, feat) in enumerate(numbered):
        try:
            one = _restricted(path, i, feat, rules, skipped, None if parsed is None else parsed[k])
        except InputError as exc:  # every feature's fault, not only the first
            faults.append(exc)
            continue
        if one is not None:
            found.append(one)
    bad = coordinate_faults(path, [f[0] for f in found], lambda k: found[k][2])
    faults.extend(bad[k] for k in sorted(bad))
    if settle:
        settle_faults(path, faults, invalid)
    found = [f for k, f in enumerate(found) if k not in bad]
    if not found:
        return []
    geoms = flag_invalid([f[0] for f in found], [f[2] for f in found], repaired)
    return [
        Feature(g, t, s, str(path), r, r.alt_min_m, r.alt_max_m)
        for g, (_, t, s, r) in zip(geoms, found)
        if not g.is_empty
    ]


def _restricted(path, i, feat, rules, skipped, parsed=None):
    """(geometry, tags, source, rule) of one restricted Feature, or None when it is not one."""
    label = f"feature {i}"
    if not isinstance(feat, dict) or feat.get("type") != "Feature":
        raise InputError(path, "not a GeoJSON Feature", label)
    props = feat.get("properties") or {}
    if not isinstance(props, dict):
        raise InputError(path, "properties must be an object", label)
    gj = feat.get("geometry")
    if gj is None:
        skipped["feature without geometry"] += 1
        return None
    if not isinstance(gj, dict) or not isinstance(gj.get("type"), str):
        raise InputError(path, "geometry must be an object with a type", label)
    try:
        geom = parsed if parsed is not None else shapely.geometry.shape(gj)
    except GeometryTypeError:
        raise InputError(path, f"unknown geometry type {gj.get('type')!r}", label) from None
    except (ValueError, TypeError, IndexError, KeyError, AttributeError, ShapelyError) as exc:
        raise InputError(path, f"malformed {gj.get('type')} geometry ({exc})", label) from None
    if geom.geom_type == "GeometryCollection":
        parts = shapely.get_parts(geom)
        parts = parts[[geomtype_of(g) is not None for g in parts]] if len(parts) else parts
        if not len(parts):
            skipped["empty geometry collection"] += 1
            return None
        dims = shapely.get_dimensions(parts)
        geom = shapely.union_all(parts[dims == dims.max()])
    gtype = geomtype_of(geom)
    if gtype is None:
        raise InputError(path, f"unsupported geometry type {geom.geom_type!r}", label)
    tags = tags_of(props)
    rule = rules.match(tags.get, gtype)
    if rule is None:
        return None
    source = source_of(feat, props, gtype, i)
    return geom, tags, source, rule
