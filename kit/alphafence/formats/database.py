"""Read a geofence database: OSM (.osm.pbf, .osm), GeoJSON, ED-269 JSON."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from alphafence.errors import InputError, need
from alphafence.formats.ed269 import looks_like_ed269, read_ed269_doc
from alphafence.formats.features import Database, select_bbox
from alphafence.formats.geojson import read_geojson_doc
from alphafence.formats.jsonfile import read_json

OSM_SUFFIXES = (".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz", ".o5m", ".opl")


def osm_wants(paths):
    """What reading ``paths`` needs beyond the base install: pyosmium (4.0 or later, for
    ``osmium.filter``) for each OSM file, as :func:`alphafence.errors.need` takes it.

    Examples
    --------
    >>> osm_wants(["malta.osm.pbf", "zones.geojson"])
    [('osmium.filter', 'reading malta.osm.pbf')]
    """
    return [
        ("osmium.filter", f"reading {p}") for p in paths if str(p).lower().endswith(OSM_SUFFIXES)
    ]


def read_file(path, rules, repaired, skipped):
    """The restricted features of one file, read by its suffix: OSM through pyosmium, JSON
    as ED-269 when it looks like it, else as GeoJSON.

    Parameters
    ----------
    path : str or Path
    rules : Rules
    repaired : list
        Sources of invalid polygons are appended.
    skipped : collections.Counter
        Reasons for features left out are counted.

    Returns
    -------
    list of Feature
        When empty, ``skipped`` says so, naming the file (one of several databases that adds
        nothing is not dropped in silence).

    Raises
    ------
    InputError
        An unknown suffix, or what the reader raised.
    """
    name, left_out = str(path).lower(), sum(skipped.values())
    if name.endswith(OSM_SUFFIXES):
        need(*osm_wants([path]))
        from alphafence.formats.osm import read_osm  # pyosmium, only when OSM is read

        features = read_osm(path, rules, repaired, skipped)
    elif name.endswith((".geojson", ".json")):
        doc = read_json(path)
        if looks_like_ed269(doc):
            features = read_ed269_doc(path, doc, rules, repaired, skipped)
        else:
            features = read_geojson_doc(path, doc, rules, repaired, skipped)
    else:
        raise InputError(
            path, "unknown database format (expected .osm.pbf, .osm, .geojson or ED-269 .json)"
        )
    if not features:
        skipped[f"all of {path}: it holds no restricted features (rules: {rules.source})"] += (
            sum(skipped.values()) - left_out
        )
    return features


def read_database(paths, rules, bbox=None, *, bbox_name="the bounding box") -> Database:
    """Read every restricted feature (by ``rules``) from the given files.

    Raises InputError with a one-line message on bad input or an empty selection
    (``bbox_name`` says what the box is in that message: the command line passes ``--bbox``).

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.formats.rules import load_rules
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> db = read_database(str(scene), load_rules())
    >>> len(db.features), db.repaired
    (16, ['way/1015'])
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    repaired, skipped, features = [], Counter(), []
    for path in paths:
        features.extend(read_file(path, rules, repaired, skipped))
    selected = select_bbox(features, bbox)
    if not selected:
        where = ", ".join(str(p) for p in paths)
        why = f" inside {bbox_name} {','.join(f'{v:g}' for v in bbox)}" if bbox else ""
        raise InputError(where, f"no restricted features{why} (rules: {rules.source})")
    return Database(selected, [str(p) for p in paths], repaired, skipped, bbox)
