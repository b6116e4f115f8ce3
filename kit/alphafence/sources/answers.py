"""A source's features read as zones, one zone per feature, each known by its id and the
hash of what it says.

A feature is read as the kit reads a file of such features: an ED-318 zone (its properties
name a zone type, authority or applicability) or a GeoJSON feature matched by the rules. A
feature that is not a zone is named (``bad``), never raised: the good ones apply. A zone's id
is its ED-318 ``identifier``, else the feature's ``id``, else its hash; the hash (SHA-256 of
its canonical JSON) says whether it changed since the last answer, so an unchanged zone is
neither read nor fenced again.
"""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from dataclasses import dataclass

from alphafence.errors import InputError
from alphafence.zones.ed269 import read_ed269_doc
from alphafence.zones.ed318 import looks_like_ed318
from alphafence.zones.features import geometry_problem
from alphafence.zones.geojson import read_geojson_doc


@dataclass(frozen=True)
class Zone:
    """One zone of a source.

    Attributes
    ----------
    id : str
    hash : str
        Of the feature's canonical JSON: a changed zone has a new one.
    feature : dict
        The GeoJSON Feature, as served.
    restricted : tuple of Feature
        What the rules make of it (empty: a feature no rule restricts).
    applicability : object
        Its ED-269/ED-318 time window (``limitedApplicability``), or None: always in force.
    """

    id: str
    hash: str
    feature: dict
    restricted: tuple
    applicability: object = None
    fence: bool = False  # a fence already (a fleet's built fences served): used as it is

    @property
    def name(self) -> str:
        """Its name where it has one, else its id."""
        for f in self.restricted:
            if f.name:
                return str(f.name)
        served = (self.feature or {}).get("properties") or {}
        return str(served.get("name") or self.id)


def canonical_hash(feature) -> str:
    """SHA-256 of ``feature``'s JSON with sorted keys (whitespace and key order do not count).

    Examples
    --------
    >>> canonical_hash({"b": 1, "a": [2]}) == canonical_hash({"a": [2], "b": 1})
    True
    """
    text = json.dumps(feature, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def zone_id(feature, digest: str) -> str:
    """The zone's id: ED-318's ``identifier``, the Feature's ``id``, or its hash's start.

    Examples
    --------
    >>> zone_id({"id": 7, "properties": {}}, "ab12"), zone_id({}, "ab12cd34ef56")
    ('7', 'sha256:ab12cd34ef56')
    """
    props = feature.get("properties") if isinstance(feature, dict) else None
    if isinstance(props, dict):
        nested = props.get("UASZone") if isinstance(props.get("UASZone"), dict) else {}
        ident = props.get("identifier") or nested.get("identifier")
        if isinstance(ident, (str, int)) and str(ident):
            return str(ident)
    if isinstance(feature, dict) and feature.get("id") not in (None, ""):
        return str(feature["id"])
    return f"sha256:{digest[:12]}"


FENCE_KINDS = ("keep_out", "keep_in", "warning")


def fence_properties(feature) -> dict | None:
    """The properties of a feature that is one of the kit's fences (``alphafence build``'s
    output served from a table: ``site_id``, ``kind``, ``method``; a PostGIS table's
    ``properties`` column holds them whole), else None.

    Examples
    --------
    >>> fence_properties({"properties": {"site_id": "x/1", "kind": "keep_out", "method": "alpha"}})
    {'site_id': 'x/1', 'kind': 'keep_out', 'method': 'alpha'}
    >>> fence_properties({"properties": {"type": "PROHIBITED"}}) is None
    True
    """
    props = feature.get("properties") if isinstance(feature, dict) else None
    if not isinstance(props, dict):
        return None
    if isinstance(props.get("properties"), dict):
        props = props["properties"]  # a table's whole-properties column
    if props.get("kind") in FENCE_KINDS and props.get("site_id") and props.get("method"):
        return props
    return None


def read_zones(url, features, rules, known=None, held=None):
    """The zones among a source's ``features``.

    Parameters
    ----------
    url : str
        The source, for messages.
    features : list
        The GeoJSON Features of an answer.
    rules : Rules
        What a plain GeoJSON feature restricts (ED-318 zones restrict by their type).
    known : dict, optional
        ``{hash: Zone}`` already read: a feature with one of these hashes is not read again.
    held : list, optional
        Given, the id of each feature that is not a zone is appended to it: a zone in force
        that comes back malformed is kept as it was, never lifted by it.

    Returns
    -------
    zones : list of Zone
        One per feature that is a zone (in the answer's order; a repeated id keeps the first).
    bad : list of str
        One line for each feature that is not a zone, naming it and what is wrong.
    """
    known = known or {}
    zones, bad, ids = [], [], set()
    for i, feature in enumerate(features):
        digest = canonical_hash(feature)
        zone = known.get(digest)
        if zone is None:
            try:
                zone = _read_one(url, i, feature, digest, rules)
            except Exception as exc:  # noqa: BLE001 - whatever a feature does, one line
                if not isinstance(exc, InputError):
                    exc = InputError(url, f"unreadable ({type(exc).__name__}: {exc})",
                                     f"feature {i}")  # fmt: skip
                bad.append(str(exc))
                if held is not None:
                    held.append(served_id(feature, digest))
                continue
        if zone.id in ids:
            bad.append(f"{url}: zone {zone.id}: served twice in one answer (the first is kept)")
            continue
        ids.add(zone.id)
        zones.append(zone)
    return zones, bad


def _read_one(url, i, feature, digest, rules) -> Zone:
    ident = zone_id(feature, digest)
    if not isinstance(feature, dict) or feature.get("type") != "Feature":
        raise InputError(url, "not a GeoJSON Feature", f"feature {i}")
    if not isinstance(feature.get("properties") or {}, dict):
        raise InputError(url, "properties must be an object", f"zone {ident}")
    if feature.get("geometry") is not None:  # its shape checked before GEOS reads it
        problem = geometry_problem(feature["geometry"])
        if problem:
            raise InputError(url, problem, f"zone {ident}")
    fence = fence_properties(feature)
    if fence is not None:
        return _read_fence(url, feature, fence, digest)
    doc = {"type": "FeatureCollection", "features": [feature]}
    repaired, skipped, invalid = [], Counter(), []
    if looks_like_ed318(doc):
        restricted = read_ed269_doc(url, doc, rules, repaired, skipped, invalid)
    else:
        restricted = read_geojson_doc(url, doc, rules, repaired, skipped, invalid)
    if invalid:
        raise InputError(url, invalid[0]["problem"], f"zone {ident}")
    props = feature.get("properties") or {}
    nested = props.get("UASZone") if isinstance(props.get("UASZone"), dict) else {}
    window = props.get("limitedApplicability", nested.get("limitedApplicability"))
    return Zone(ident, digest, feature, tuple(restricted), window)


def served_id(feature, digest: str) -> str:
    """The id a feature's zone has when read: a served fence's (its ``id``, else
    ``site_id#kind``), else :func:`zone_id`'s.

    Examples
    --------
    >>> served_id({"properties": {"site_id": "x/1", "kind": "keep_out", "method": "alpha"}}, "ab")
    'x/1#keep_out'
    """
    fence = fence_properties(feature)
    if fence is None:
        return zone_id(feature, digest)
    return str(feature.get("id") or f"{fence['site_id']}#{fence['kind']}")


def _read_fence(url, feature, props, digest) -> Zone:
    """A served fence (checked as a fence file's feature is where it is fenced:
    :func:`alphafence.fencing.zone_fences.read_answer`)."""
    import shapely

    ident = served_id(feature, digest)
    try:
        geometry = shapely.geometry.shape(feature.get("geometry") or {})
    except Exception as exc:  # noqa: BLE001 - GEOS's or shapely's words, in one line
        raise InputError(url, f"unreadable geometry: {exc}", f"fence {ident}") from None
    if geometry.is_empty:
        raise InputError(url, "empty geometry", f"fence {ident}")
    window = (props.get("zone") or {}).get("applicability")
    served = {"type": "Feature", "properties": props, "geometry": feature["geometry"]}
    return Zone(ident, digest, served, (), window, fence=True)
