"""Large GeoJSON read as a stream: GeoJSON text sequences line by line, FeatureCollections
feature by feature (ijson), in batches, so memory holds one batch and the restricted features.

A GeoJSON text sequence (RFC 8142, ``.geojsonl``, ``.geojsons``, ``.geojsonseq``, ``.ndjson``)
holds one Feature per record: a record starts with the RS character (0x1e) or is one line.
"""

from __future__ import annotations

import codecs
import io
import json
import os
from typing import NamedTuple

from alphafence.errors import InputError, need
from alphafence.zones.features import settle_faults
from alphafence.zones.geojson import features_of
from alphafence.zones.jsonfile import max_json_bytes

SEQ_SUFFIXES = (".geojsonl", ".geojsons", ".geojsonseq", ".ndjson", ".jsonl")
RS = "\x1e"
STREAM_ABOVE_BYTES = 64 * 2**20  # a FeatureCollection larger than this is streamed
BATCH = 2_000  # features parsed per batch (fewer live objects for the cyclic GC to traverse)
TEXT_BLOCK = 8192  # bytes a text file is decoded at a time (io.TextIOWrapper's chunk size)
SCAN_BLOCK = 8 * 2**20  # bytes scanned at a time for record boundaries


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


def sequence_records(fh, path, lineno=0, index=0, skip=0):
    """``(index, Feature object, its text)`` for each record of a GeoJSON text sequence
    (``(index, Feature object)`` for the members of a FeatureCollection record).

    Parameters
    ----------
    fh : iterable of str
        The text's lines.
    path : str or Path
        The file, for messages.
    lineno, index : int
        Lines and records before ``fh``'s first line (a part of a file read on its own).
    skip : int
        Lines of ``fh`` passed over unread (parts of the file read elsewhere).

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
    for number, line in enumerate(fh, lineno + 1):
        if number <= skip:
            continue
        text = line.strip().lstrip(RS).strip()
        if not text:
            continue
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(
                path, f"malformed JSON at line {number} column {exc.colno}: {exc.msg}"
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


def iter_geojson(
    path, rules, repaired, skipped, batch=BATCH, skip=(0, 0), invalid=None, faults=None
):
    """The restricted features of a large GeoJSON file, in batches (lists of Feature).

    Parameters
    ----------
    path : str or Path
        A GeoJSON text sequence or a FeatureCollection.
    rules, repaired, skipped
        As for :func:`alphafence.zones.geojson.read_geojson_doc`.
    batch : int
        Features parsed per batch.
    skip : tuple of int
        ``(lines, records)`` of a text sequence already read (by :func:`read_chunk`): passed
        over unparsed, the records after them numbered from ``records`` on.
    invalid : list, optional
        As for :func:`alphafence.zones.geojson.read_geojson_doc`: malformed features are
        left out and described here, or (None) raised at the file's end, all at once.
    faults : list, optional
        Where a reader of the file's other parts gathers the faults (InputErrors): appended
        to, for that reader to settle.

    Yields
    ------
    list of Feature

    Raises
    ------
    InputError
        Naming the file and the feature: malformed JSON at once; malformed features at the
        end, all of them (one line each).

    Examples
    --------
    >>> import tempfile, os
    >>> from collections import Counter
    >>> from alphafence.zones.rules import load_rules
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
        if is_sequence(path):
            records = sequence_records(fh, path, index=skip[1], skip=skip[0])
        else:
            records = collection_records(fh, path)
        chunk, texts, settle = [], [], faults is None
        faults = [] if faults is None else faults
        try:
            for item in records:
                chunk.append(item[:2])
                texts.append(item[2] if len(item) > 2 else None)
                if len(chunk) >= batch:
                    yield features_of(
                        path, chunk, rules, repaired, skipped, _geometries(texts), faults=faults
                    )
                    chunk, texts = [], []
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text ({exc.reason})") from None
        if chunk:
            yield features_of(
                path, chunk, rules, repaired, skipped, _geometries(texts), faults=faults
            )
        if settle:
            settle_faults(path, faults, invalid)


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


class SeqChunk(NamedTuple):
    """A part of a GeoJSON text sequence that holds whole lines, to be read on its own.

    Attributes
    ----------
    offset, end : int
        Its first byte and one past its last.
    line : int
        The number of its first line (from 1).
    index : int
        The index of its first record in the file.
    records : int or None
        Records it holds, as the scan counted them (a FeatureCollection line counts one);
        None: the rest of the file, which the scan could not split (lines that end in a bare
        carriage return), read with :func:`iter_geojson`.
    """

    offset: int
    end: int
    line: int
    index: int
    records: int | None


class Unchunkable(Exception):
    """A chunk that cannot be read apart from the rest of its file as the whole file's reader
    reads it: it is not UTF-8 up to the end of the text block it ends in, or it holds a
    FeatureCollection record, or not the records the scan counted."""


def sequence_chunks(path, batch=BATCH):
    """A GeoJSON text sequence cut, in binary, into chunks of ``batch`` records (the last may
    hold fewer), each knowing its first line's number and its first record's index, so that
    reading the chunks apart (:func:`read_chunk`) reads the batches :func:`iter_geojson`
    reads. A line counts as a record unless blank (whitespace and RS only).

    Yields
    ------
    SeqChunk

    Examples
    --------
    >>> import tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = os.path.join(d, "x.geojsonl")
    ...     _ = open(path, "wb").write(b'{"a": 1}\\n\\n\\x1e{"b": 2}\\n{"c": 3}\\n')
    ...     list(sequence_chunks(path, batch=2))
    [SeqChunk(offset=0, end=20, line=1, index=0, records=2), SeqChunk(offset=20, end=29, \
line=4, index=2, records=1)]
    """
    import numpy as np

    with open(path, "rb") as fh:
        start, line, index, records = 0, 1, 0, 0  # the chunk being counted
        carry, base, base_line = b"", 0, 1  # bytes not yet counted, their offset, line
        while True:
            block = fh.read(SCAN_BLOCK)
            data = carry + block if carry else block
            arr = np.frombuffer(data, np.uint8)
            ends = np.flatnonzero(arr == 10) + 1  # each line's end, newline included
            if not block and (ends[-1] if len(ends) else 0) < len(data):
                ends = np.append(ends, len(data))  # the last line has no newline
            starts = np.concatenate(([0], ends[:-1]))
            if len(ends):
                head = arr[starts]
                second = arr[np.minimum(starts + 1, len(data) - 1)]
                recs = ((head == 123) | ((head == 30) & (second == 123))).astype(np.int64)
                lone = np.flatnonzero(arr[: ends[-1]] == 13) if b"\r" in data else ends[:0]
                lone = lone[arr[np.minimum(lone + 1, len(data) - 1)] != 10]  # not CR LF
                stop = int(np.searchsorted(ends, lone[0], side="right")) if len(lone) else len(ends)
                for i in np.flatnonzero(recs[:stop] == 0):  # anything but "{" or RS "{" first
                    text = data[starts[i] : ends[i]].decode("utf-8", "surrogateescape")
                    recs[i] = bool(text.strip().lstrip(RS).strip())
                cum = np.cumsum(recs[:stop]) + records
                for i in np.searchsorted(cum, np.arange(batch, cum[-1] + 1 if stop else 0, batch)):
                    yield SeqChunk(start, base + int(ends[i]), line, index, batch)
                    start, line, index = base + int(ends[i]), base_line + int(i) + 1, index + batch
                records = int(cum[-1]) % batch if stop else records
                if len(lone):
                    yield SeqChunk(start, -1, line, index, None)
                    return
                base, base_line = base + int(ends[-1]), base_line + len(ends)
                carry = data[int(ends[-1]) :]
            else:
                carry = data
            if not block:
                break
        if records:
            yield SeqChunk(start, base, line, index, records)


def read_chunk(path, chunk, rules, repaired, skipped, faults):
    """The restricted features of one chunk of a GeoJSON text sequence, read as
    :func:`iter_geojson` reads the batch it is, messages naming the file's own line and
    feature numbers.

    Parameters
    ----------
    path : str or Path
    chunk : SeqChunk
        From :func:`sequence_chunks` (with a record count).
    rules, repaired, skipped
        As for :func:`iter_geojson`.
    faults : list
        The malformed features' InputErrors are appended (the file's reader settles them).

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        Malformed JSON, as :func:`iter_geojson` raises it reading this batch.
    Unchunkable
        The chunk must be read with the rest of the file, by :func:`iter_geojson`.
    """
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        # the whole reader decodes the text block this chunk ends in before its last line
        upto = min(size, -(-chunk.end // TEXT_BLOCK) * TEXT_BLOCK)
        data = os.pread(fh.fileno(), upto - chunk.offset, chunk.offset)
    try:
        codecs.getincrementaldecoder("utf-8")().decode(data, upto >= size)
    except UnicodeDecodeError:
        raise Unchunkable(path) from None
    lines = io.TextIOWrapper(io.BytesIO(data[: chunk.end - chunk.offset]), encoding="utf-8")
    numbered, texts = [], []
    for item in sequence_records(lines, path, chunk.line - 1, chunk.index):
        if len(item) < 3:  # a FeatureCollection's member: the count is the scan's no more
            raise Unchunkable(path)
        numbered.append(item[:2])
        texts.append(item[2])
    if len(numbered) != chunk.records:
        raise Unchunkable(path)
    return features_of(path, numbered, rules, repaired, skipped, _geometries(texts), faults=faults)
