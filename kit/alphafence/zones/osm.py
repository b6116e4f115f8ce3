"""OpenStreetMap .osm.pbf / .osm through pyosmium.

Areas come from closed ways and multipolygon relations (libosmium's area assembler),
points from tagged nodes, lines from tagged open ways. Only objects carrying a key
that some rule looks at are assembled, which keeps a country extract fast.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import osmium
import shapely
from osmium.filter import KeyFilter

from alphafence.errors import InputError
from alphafence.zones.features import Feature, check_coordinates, flag_invalid, geomtype_of


def read_osm(path, rules, repaired, skipped):
    """The restricted features of an OSM file (``.osm.pbf``, ``.osm``...), streamed; all of
    them in one list (see :func:`iter_osm` for batches).

    Parameters
    ----------
    path : str or Path
    rules : Rules
        Only objects with a key some rule looks at are assembled.
    repaired : list
        Sources of invalid polygons are appended (they are repaired later).
    skipped : collections.Counter
        Reasons for objects left out are counted.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        No such file, or not readable as OSM.
    """
    return [f for batch in iter_osm(path, rules, repaired, skipped) for f in batch]


def iter_osm(path, rules, repaired, skipped, batch=20_000):
    """The restricted features of an OSM file in batches (lists of Feature) as the file is
    read, so a country's features need not be held at once.

    Parameters
    ----------
    path, rules, repaired, skipped
        As for :func:`read_osm`.
    batch : int
        Features per batch.

    Yields
    ------
    list of Feature
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    keys = rules.keys
    if not keys:
        return
    wkb = osmium.geom.WKBFactory()
    blobs, tags_list, sources, rule_list = [], [], [], []
    try:
        fp = (
            osmium.FileProcessor(str(path))
            .with_locations()
            .with_areas(KeyFilter(*keys))
            .with_filter(KeyFilter(*keys))
        )
        for obj in fp:
            if obj.is_relation():
                continue  # multipolygons arrive as areas
            if obj.is_area():
                gtype = "area"
                source = f"{'way' if obj.from_way() else 'relation'}/{obj.orig_id()}"
            elif obj.is_node():
                gtype = "point"
                source = f"node/{obj.id}"
            else:  # way
                if obj.is_closed() and len(obj.nodes) >= 4:
                    continue  # assembled as an area
                gtype = "line"
                source = f"way/{obj.id}"
            tags = obj.tags
            rule = rules.match(tags.get, gtype)
            if rule is None:
                continue
            try:
                if gtype == "area":
                    blob = wkb.create_multipolygon(obj)
                elif gtype == "point":
                    blob = wkb.create_point(obj)
                else:
                    blob = wkb.create_linestring(obj)
            except (osmium.InvalidLocationError, RuntimeError):
                skipped[f"{gtype} with missing or invalid nodes"] += 1
                continue
            blobs.append(blob)
            tags_list.append(dict(tags))
            sources.append(source)
            rule_list.append(rule)
            if len(blobs) >= batch:
                yield _features(path, blobs, tags_list, sources, rule_list, repaired, skipped)
                blobs, tags_list, sources, rule_list = [], [], [], []
    except (RuntimeError, ValueError, OSError) as exc:
        raise InputError(path, f"not a readable OSM file ({exc})") from None
    if blobs:
        yield _features(path, blobs, tags_list, sources, rule_list, repaired, skipped)


def _features(path, blobs, tags_list, sources, rule_list, repaired, skipped):
    geoms = shapely.from_wkb(np.array(blobs, dtype=object))
    check_coordinates(path, geoms, lambda i: sources[i])
    geoms = flag_invalid(geoms, sources, repaired)
    out = []
    for g, tags, src, rule in zip(geoms, tags_list, sources, rule_list):
        if g.is_empty or geomtype_of(g) is None:
            skipped["empty after repair"] += 1
            continue
        out.append(Feature(g, tags, src, str(path), rule, rule.alt_min_m, rule.alt_max_m))
    return out
