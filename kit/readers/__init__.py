"""Read a geofence database: OSM (.osm.pbf, .osm), GeoJSON, ED-269 JSON."""

from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

from kit.errors import InputError
from kit.features import Database, select_bbox
from kit.readers.ed269 import looks_like_ed269, read_ed269_doc
from kit.readers.geojson import read_geojson_doc
from kit.readers.osm import read_osm

OSM_SUFFIXES = (".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz", ".o5m", ".opl")


MAX_JSON_MB_DEFAULT = 512  # JSON is parsed whole: refuse what would not fit, before reading it


def max_json_bytes() -> int:
    return int(float(os.environ.get("ALPHAFENCE_MAX_JSON_MB", MAX_JSON_MB_DEFAULT)) * 1024 * 1024)


def read_json(path):
    try:
        size = os.path.getsize(path)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    limit = max_json_bytes()
    if size > limit:
        raise InputError(
            path,
            f"{size / 2**20:.0f} MB of JSON is more than the {limit / 2**20:.0f} MB limit "
            "(set ALPHAFENCE_MAX_JSON_MB to allow more, or use .osm.pbf, which is streamed)",
        )
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise InputError(
            path, f"malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None


def read_file(path, rules, repaired, skipped):
    name = str(path).lower()
    if name.endswith(OSM_SUFFIXES):
        return read_osm(path, rules, repaired, skipped)
    if name.endswith((".geojson", ".json")):
        doc = read_json(path)
        if looks_like_ed269(doc):
            return read_ed269_doc(path, doc, rules, repaired, skipped)
        return read_geojson_doc(path, doc, rules, repaired, skipped)
    raise InputError(
        path, "unknown database format (expected .osm.pbf, .osm, .geojson or ED-269 .json)"
    )


def read_database(paths, rules, bbox=None) -> Database:
    """Read every restricted feature (by ``rules``) from the given files.

    Raises InputError with a one-line message on bad input or an empty selection.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    repaired, skipped, features = [], Counter(), []
    for path in paths:
        features.extend(read_file(path, rules, repaired, skipped))
    selected = select_bbox(features, bbox)
    if not selected:
        where = ", ".join(str(p) for p in paths)
        why = f" inside --bbox {','.join(f'{v:g}' for v in bbox)}" if bbox else ""
        raise InputError(where, f"no restricted features{why} (rules: {rules.source})")
    return Database(selected, [str(p) for p in paths], repaired, skipped, bbox)
