"""Large GeoJSON read as a stream: GeoJSON text sequences line by line, FeatureCollections
feature by feature (ijson), in batches, so memory holds one batch and the restricted features.

A GeoJSON text sequence (RFC 8142, ``.geojsonl``, ``.geojsons``, ``.geojsonseq``, ``.ndjson``)
holds one Feature per record: a record starts with the RS character (0x1e) or is one line.
"""

from __future__ import annotations

import json
import os

from alphafence.errors import InputError, need
from alphafence.formats.geojson import features_of
from alphafence.formats.jsonfile import max_json_bytes

SEQ_SUFFIXES = (".geojsonl", ".geojsons", ".geojsonseq", ".ndjson", ".jsonl")
RS = "\x1e"
STREAM_ABOVE_BYTES = 64 * 2**20  # a FeatureCollection larger than this is streamed
BATCH = 20_000  # features parsed per batch


def is_sequence(path) -> bool:
    """True for the suffixes of GeoJSON text sequences.

    Examples
    --------
    >>> is_sequence("zones.geojsonl"), is_sequence("zones.geojson")
    (True, False)
    """
    return str(path).lower().endswith(SEQ_SUFFIXES)


# keys of ED-269 and ED-318 zones, which are read whole (and refused above the JSON limit)
ZONE_MARKERS = ('"UASZoneList"', '"horizontalProjection"', '"zoneAuthority"', '"restriction":')


def should_stream(path) -> bool:
    """True when ``path`` is read as a stream: a text sequence, or a GeoJSON FeatureCollection
    larger than 64 MB (or than ``$ALPHAFENCE_MAX_JSON_MB``, above which it cannot be read
    whole) whose first 64 kB show no ED-269 or ED-318 zone keys."""
    if is_sequence(path):
        return True
    try:
        size = os.path.getsize(path)
        if size <= min(STREAM_ABOVE_BYTES, max_json_bytes()):
            return False
        with open(path, "rb") as fh:
            head = fh.read(65536).decode("utf-8", "replace").replace(" ", "")
    except OSError:
        return False
    return '"FeatureCollection"' in head and not any(m in head for m in ZONE_MARKERS)


def sequence_records(fh, path):
    """``(index, Feature object, its text)`` for each record of a GeoJSON text sequence
    (``(index, Feature object)`` for the members of a FeatureCollection record).

    Raises
    ------
    InputError
        Malformed JSON, naming the line.

    Examples
    --------
    >>> import io
    >>> text = '\\x1e{"type": "Feature", "id": 1}\\n\\n{"type": "Feature", "id": 2}\\n'
    >>> [(r[0], r[1]["id"]) for r in sequence_records(io.StringIO(text), "x.geojsonl")]
    [(0, 1), (1, 2)]
    """
    index = 0
    for lineno, line in enumerate(fh, 1):
        text = line.strip().lstrip(RS).strip()
        if not text:
            continue
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(
                path, f"malformed JSON at line {lineno} column {exc.colno}: {exc.msg}"
            ) from None
        if isinstance(obj, dict) and obj.get("type") == "FeatureCollection":
            for feat in obj.get("features") or []:
                yield index, feat
                index += 1
            continue
        yield index, obj, text
        index += 1


def collection_records(fh, path):
    """``(index, Feature object)`` for each member of a FeatureCollection's ``features``, parsed
    one at a time with ijson (its C backend when built).

    Raises
    ------
    InputError
        Malformed JSON, or not a FeatureCollection with features.
    """
    need(("ijson", f"streaming {path}"))
    import ijson

    count = 0
    try:
        for count, feat in enumerate(ijson.items(fh, "features.item", use_float=True), 1):
            yield count - 1, feat
    except ijson.JSONError as exc:
        raise InputError(path, f"malformed JSON ({exc})") from None
    if count == 0:
        fh.seek(0)
        try:
            kind = next(ijson.items(fh, "type"), None)
        except ijson.JSONError as exc:
            raise InputError(path, f"malformed JSON ({exc})") from None
        if kind != "FeatureCollection":
            raise InputError(path, "not a GeoJSON FeatureCollection")


def iter_geojson(path, rules, repaired, skipped, batch=BATCH):
    """The restricted features of a large GeoJSON file, in batches (lists of Feature).

    Parameters
    ----------
    path : str or Path
        A GeoJSON text sequence or a FeatureCollection.
    rules, repaired, skipped
        As for :func:`alphafence.formats.geojson.read_geojson_doc`.
    batch : int
        Features parsed per batch.

    Yields
    ------
    list of Feature

    Raises
    ------
    InputError
        A one-line message naming the file and the feature.

    Examples
    --------
    >>> import tempfile, os
    >>> from collections import Counter
    >>> from alphafence.formats.rules import load_rules
    >>> line = ('{"type": "Feature", "properties": {"amenity": "hospital"}, "geometry": '
    ...         '{"type": "Point", "coordinates": [14.5, 35.9]}}')
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = os.path.join(d, "h.geojsonl")
    ...     _ = open(path, "w").write(line + "\\n" + line + "\\n")
    ...     [len(b) for b in iter_geojson(path, load_rules(), [], Counter(), batch=1)]
    [1, 1]
    """
    try:
        fh = open(path, encoding="utf-8") if is_sequence(path) else open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    with fh:
        records = sequence_records(fh, path) if is_sequence(path) else collection_records(fh, path)
        chunk, texts = [], []
        try:
            for item in records:
                chunk.append(item[:2])
                texts.append(item[2] if len(item) > 2 else None)
                if len(chunk) >= batch:
                    yield features_of(path, chunk, rules, repaired, skipped, _geometries(texts))
                    chunk, texts = [], []
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text ({exc.reason})") from None
        if chunk:
            yield features_of(path, chunk, rules, repaired, skipped, _geometries(texts))


def _geometries(texts):
    """Each Feature text's geometry read by GEOS in one vectorised call (twice as fast as
    building it from the parsed object), None where there is no text or GEOS refuses it.
    Collections and invalid shapes are left to the parsed object (tested to give the same
    features as the whole-document reader)."""
    import numpy as np
    import shapely

    out = np.full(len(texts), None, dtype=object)
    idx = np.flatnonzero([t is not None for t in texts])
    if idx.size:
        geoms = shapely.from_geojson(
            np.array([texts[i] for i in idx], dtype=object), on_invalid="ignore"
        )
        collection = shapely.get_type_id(geoms) == shapely.GeometryType.GEOMETRYCOLLECTION
        # degenerate shapes (a ring of three points...) are left to the parsed object too:
        # shapely's constructors mend them differently from GEOS's reader
        out[idx] = np.where(collection | ~shapely.is_valid(geoms), None, geoms)
    return out
