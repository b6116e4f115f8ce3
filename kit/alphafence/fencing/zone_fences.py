"""Fences for a live source's zones, each zone fenced on its own.

A source's zones come and go one by one (a closure added, a window ended), so each is its own
site or sites: a zone's fences never depend on another zone, an unchanged zone is never fenced
again, and zones with different time windows, restrictions or altitude bands are never merged.
Each fence's properties name the zone (``source_zone``) and the version (``source_hash``) it
was made from. Runs in the monitor's worker process (:mod:`alphafence.monitor.live`) and in
``build --source``.
"""

from __future__ import annotations

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
        ``("new", Zone)``; one line per feature that is not a zone; ``{hash: [(properties,
        WKB)]}`` of the new zones' fences, each checked here as a fence file's feature is
        (:func:`unpack` makes them fence records: plain data crosses the process boundary
        cheaply, where shapely objects would be rebuilt one by one in the monitor).
    """
    from alphafence.sources.answers import canonical_hash, read_zones, zone_id

    if features and isinstance(features[0], (bytes, bytearray)):
        import json

        features = [f for page in features for f in json.loads(page)["features"]]
    entries, fresh, order = [], [], []
    for feature in features:
        digest = canonical_hash(feature)
        if digest in known:
            order.append(("known", zone_id(feature, digest), digest))
        else:
            order.append(None)
            fresh.append(feature)
    zones, bad = read_zones(url, fresh, rules)
    zones = [z for z in zones if not z.fence or _fence_ok(url, z, bad)]
    by_hash = {z.hash: z for z in zones}
    fresh_hashes = iter(canonical_hash(f) for f in fresh)
    for item in order:
        if item is not None:
            entries.append(item)
            continue
        digest = next(fresh_hashes)
        if digest in by_hash:
            entries.append(("new", by_hash.pop(digest)))
    fences = zone_fence_features([e[1] for e in entries if e[0] == "new"], rules, options)
    return entries, bad, {h: _records(url, h, feats) for h, feats in fences.items()}


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


def _fence_ok(url, zone, bad) -> bool:
    """Whether a served fence reads as a fence file's feature does (else its line in ``bad``)."""
    import shapely

    from alphafence.errors import InputError
    from alphafence.fencefiles.fence_geojson import fence_record

    props = zone.feature["properties"]
    try:
        fence_record(url, props, shapely.geometry.shape(zone.feature["geometry"]),
                     f"fence {zone.id}", 0)  # fmt: skip
    except InputError as exc:
        bad.append(str(exc))
        return False
    return True
