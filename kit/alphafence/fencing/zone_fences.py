"""Fences for a live source's zones, each zone fenced on its own.

A source's zones come and go one by one (a closure added, a window ended), so each is its own
site or sites: a zone's fences never depend on another zone, an unchanged zone is never fenced
again, and zones with different time windows, restrictions or altitude bands are never merged.
Each fence's properties name the zone (``source_zone``) and the version (``source_hash``) it
was made from. Runs in the monitor's worker process (:mod:`alphafence.monitor.live`) and in
``build --source``.
"""

from __future__ import annotations

import contextlib
import os


def zone_fence_features(zones, rules, options=None) -> dict:
    """The fences of each zone, as fence GeoJSON Features.

    Parameters
    ----------
    zones : iterable of Zone
        From :func:`alphafence.sources.answers.read_zones`.
    rules : Rules
    options : BuildOptions, optional

    Returns
    -------
    dict
        ``{zone hash: [Feature, ...]}`` (plain dicts: they cross process boundaries); a zone
        no rule restricts has none.

    Examples
    --------
    >>> from alphafence.sources.answers import read_zones
    >>> from alphafence.zones.rules import load_rules
    >>> square = {"type": "Polygon", "coordinates": [[[14.5, 35.9], [14.501, 35.9],
    ...           [14.501, 35.901], [14.5, 35.901], [14.5, 35.9]]]}
    >>> zone = {"type": "Feature", "id": "closure-7", "geometry": square,
    ...         "properties": {"identifier": "closure-7", "type": "PROHIBITED",
    ...                        "zoneAuthority": [{"name": "police"}]}}
    >>> zones, bad = read_zones("https://zones.example", [zone], load_rules())
    >>> out = zone_fence_features(zones, load_rules())
    >>> [(f["properties"]["kind"], f["properties"]["source_zone"]) for f in out[zones[0].hash]]
    [('keep_out', 'closure-7'), ('warning', 'closure-7')]
    """
    from alphafence.fencefiles.fence_geojson import fence_features
    from alphafence.fencing.pipeline import BuildOptions, build_fences
    from alphafence.fencing.sites import group_sites

    options = options or BuildOptions()
    out, sites, owner = {}, [], {}
    for zone in zones:
        out[zone.hash] = []
        if zone.fence:  # a fence already: used as served
            props = {**zone.feature["properties"], "source_zone": zone.id, "source_hash": zone.hash}
            out[zone.hash] = [{**zone.feature, "properties": props}]
            continue
        # each zone's own sites (never merged with another zone's), fenced all at once below
        for site in group_sites(list(zone.restricted), rules, options.join_m):
            if site.site_id in owner:  # two zones' sites named alike: told apart by a suffix
                site.site_id = f"{site.site_id}#{zone.hash[:8]}"
            owner[site.site_id] = zone
            sites.append(site)
    if sites:
        result = build_fences([], rules, options, sites=sites)
        for fence, feature in zip(result.fences, fence_features(result.fences)):
            zone = owner[fence.site_id]
            props = {**feature["properties"], "source_zone": zone.id, "source_hash": zone.hash}
            out[zone.hash].append({**feature, "properties": props})
    return out


def worker_start() -> None:
    """A fencing worker's start: below the companion's priority (the autopilot's margin and the
    position checks come first)."""
    try:
        os.nice(10)
    except OSError:
        pass


def read_answer(url, features, rules, options, known) -> tuple:
    """A source's answer read and its new zones fenced: the worker process's job.

    Parameters
    ----------
    url : str
        The source, for messages.
    features : list of dict, or list of bytes
        The answer's GeoJSON Features, or its pages' bodies as they came (FeatureCollections'
        JSON: read here).
    rules : Rules
    options : BuildOptions
    known : set of str
        Hashes of the zones already read and fenced: not read again.

    Returns
    -------
    tuple
        ``(entries, bad, fences)``: per zone, in order, ``("known", id, hash)`` or
        ``("new", Zone)``, then ``("held", id, None)`` for each feature that is not a zone (or
        cannot be fenced), to be kept as it was if it is in force; one line per such feature; ``{hash: [(properties,
        WKB)]}`` of the new zones' fences, each checked here as a fence file's feature is
        (:func:`unpack` makes them fence records: plain data crosses the process boundary
        cheaply, where shapely objects would be rebuilt one by one in the monitor).
    """
    from alphafence.sources.answers import canonical_hash, read_zones, served_id
    from alphafence.sources.request import loads

    if features and isinstance(features[0], (bytes, bytearray)):
        features = [f for page in features for f in loads(url, page)["features"]]
    entries, fresh, order = [], [], []
    for feature in features:
        digest = canonical_hash(feature)
        if digest in known:
            order.append(("known", served_id(feature, digest), digest))
        else:
            order.append(None)
            fresh.append(feature)
    held = []
    zones, bad = read_zones(url, fresh, rules, held=held)
    zones = [z for z in zones if not z.fence or _fence_ok(url, z, bad, held)]
    fences = _fenced(url, zones, rules, options, bad, held)
    by_hash = {z.hash: z for z in zones if z.hash in fences}
    fresh_hashes = iter(canonical_hash(f) for f in fresh)
    for item in order:
        if item is not None:
            entries.append(item)
            continue
        digest = next(fresh_hashes)
        if digest in by_hash:
            entries.append(("new", by_hash.pop(digest)))
    entries += [("held", ident, None) for ident in held]
    return entries, bad, fences


def _fenced(url, zones, rules, options, bad, held) -> dict:
    """``{hash: [(properties, WKB)]}`` of ``zones``' fences: all at once, or, when that fails,
    zone by zone, a zone that cannot be fenced named in ``bad`` and held (never lifted by it)."""
    from alphafence.errors import InputError

    def fence(some):
        return {
            h: _records(url, h, f) for h, f in zone_fence_features(some, rules, options).items()
        }

    with contextlib.suppress(Exception):  # else one zone's fault: found below, zone by zone
        return fence(zones)
    out = {}
    for z in zones:
        try:
            out.update(fence([z]))
        except Exception as exc:  # noqa: BLE001 - whatever the fencing raised, one line
            bad.append(str(InputError(url, f"cannot be fenced ({type(exc).__name__}: {exc})",
                                      f"zone {z.id}")))  # fmt: skip
            held.append(z.id)
    return out


def _records(url, digest, features) -> list:
    import shapely

    from alphafence.fencefiles.fence_geojson import fence_record

    out = []
    for k, f in enumerate(features):
        geometry = shapely.geometry.shape(f["geometry"])
        fence_record(url, f["properties"], geometry, f"zone {f['properties']['source_zone']}", k)
        out.append((f["properties"], shapely.to_wkb(geometry)))
    return out


def unpack(url, packed) -> list:
    """Fence records from :func:`read_answer`'s ``(properties, WKB)`` pairs (checked in the
    worker already), their geometries read in one vectorised call."""
    import numpy as np
    import shapely

    from alphafence.fencefiles.fence_geojson import fence_record

    if not packed:
        return []
    geoms = shapely.from_wkb(np.array([w for _, w in packed], dtype=object))
    return [fence_record(url, p, g, f"zone {p.get('source_zone')}", k)
            for k, ((p, _), g) in enumerate(zip(packed, geoms))]  # fmt: skip


def _fence_ok(url, zone, bad, held) -> bool:
    """Whether a served fence reads as a fence file's feature does (else its line in ``bad``)."""
    import shapely

    from alphafence.errors import InputError
    from alphafence.fencefiles.fence_geojson import fence_record

    props = zone.feature["properties"]
    try:
        fence_record(url, props, shapely.geometry.shape(zone.feature["geometry"]),
                     f"fence {zone.id}", 0)  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - whatever the check raised, one line
        if not isinstance(exc, InputError):
            exc = InputError(url, f"unreadable ({type(exc).__name__}: {exc})", f"fence {zone.id}")
        bad.append(str(exc))
        held.append(zone.id)
        return False
    return True
