"""A GeoJSON text sequence read in worker processes (fencing/read_jobs.py) reads exactly what the
main process reads alone: the same spool (records, extents, widths, classes, tables), the
same repaired and skipped notes in the same order, the same first error with the same line
number, the same malformed features all at once (or left out with ``--skip-invalid``), and a
build writes the same bytes. Cut into chunks of a few records to read many."""

from __future__ import annotations

import json
from collections import Counter
from concurrent.futures import Future

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import alphafence.fencing.tiled as tiled
from alphafence.errors import InputError
from alphafence.fencefiles.fence_stream import open_writers
from alphafence.fencing.pipeline import BuildOptions
from alphafence.fencing.read_jobs import ReadChunk, sequence_reader
from alphafence.fencing.sites import feature_widths, site_class
from alphafence.fencing.spool import Spool
from alphafence.fencing.tile_jobs import start_pool
from alphafence.zones.database import DatabaseStream
from alphafence.zones.features import select_bbox
from alphafence.zones.geojson_stream import RS, TEXT_BLOCK, iter_geojson, sequence_chunks
from alphafence.zones.rules import parse_rules

RULES = parse_rules(
    {
        "defaults": {"point_radius_m": 20.0, "line_width_m": 8.0},
        "rule": [
            {"category": "school", "kind": "keep_out", "tags": {"amenity": "school"}},
            {"category": "park", "kind": "warning", "tags": {"leisure": "park"}},
            {
                "category": "tower",
                "kind": "keep_out",
                "tags": {"man_made": "tower"},
                "margin_m": 5.0,
                "alt_max_m": 120.0,
            },
        ],
    }
)
TAGS = [{"amenity": "school"}, {"leisure": "park"}, {"man_made": "tower"}, {"shop": "bakery"}]


class Inline:
    """An executor that runs each task as it is submitted, in this process."""

    def submit(self, fn, *args):
        future = Future()
        try:
            future.set_result(fn(*args))
        except BaseException as exc:  # noqa: BLE001 (handed over, as a pool does)
            future.set_exception(exc)
        return future


def _feature(i, tags, shape="box", fid=True):
    x, y = 14.4 + (i % 17) * 0.003, 35.8 + (i // 17) * 0.003
    geom = {
        "box": {
            "type": "Polygon",
            "coordinates": [[[x, y], [x + 1e-3, y], [x + 1e-3, y + 1e-3], [x, y]]],
        },
        "point": {"type": "Point", "coordinates": [x, y]},
        "line": {"type": "LineString", "coordinates": [[x, y], [x + 2e-3, y + 1e-3]]},
        "bowtie": {
            "type": "Polygon",
            "coordinates": [[[x, y], [x + 1e-3, y + 1e-3], [x + 1e-3, y], [x, y + 1e-3], [x, y]]],
        },
        "none": None,
        "empty": {"type": "GeometryCollection", "geometries": []},
    }[shape]
    feat = {"type": "Feature", "properties": dict(tags), "geometry": geom}
    if fid:
        feat["id"] = f"f{i}"
    return json.dumps(feat)


def _lines(n):
    """Features of every kind the readers treat apart, blank lines, RS and CRLF records."""
    shapes = ["box", "point", "line", "box", "bowtie", "none", "empty"]
    out = []
    for i in range(n):
        text = _feature(i, TAGS[i % 4], shapes[i % 7], fid=i % 3 != 0)
        out.append({0: text, 1: RS + text, 2: " " + text + " ", 3: text + "\r"}[i % 4])
        if i % 5 == 0:
            out.append(["", "  ", RS, " \t"][i % 4])
    return out


def _write(path, lines):
    path.write_bytes("".join(line + "\n" for line in lines).encode())
    return str(path)


def _spool_of(parts):
    spool = Spool()
    for part in parts:
        if isinstance(part, ReadChunk):
            part.add_to(spool, RULES)
        else:
            classes = [spool.class_of(site_class(f)) for f in part]
            spool.add(part, feature_widths(part, RULES), classes)
    return spool


def _serial(path, bbox=None, batch=5):
    repaired, skipped = [], Counter()
    try:
        parts = [select_bbox(p, bbox) for p in iter_geojson(path, RULES, repaired, skipped, batch)]
    except InputError as exc:
        return str(exc)
    return _spool_of(p for p in parts if len(p)), repaired, skipped


def _parallel(path, bbox=None, batch=5, pool=None):
    repaired, skipped = [], Counter()
    read = sequence_reader(pool or Inline(), 3, batch)
    try:
        parts = [p for p in read(path, RULES, bbox, repaired, skipped) if len(p)]
    except InputError as exc:
        return str(exc)
    return _spool_of(parts), repaired, skipped


def assert_same_read(a, b):
    """Both refused with the same message, or the same spool, notes and order."""
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    (sa, ra, ka), (sb, rb, kb) = a, b
    n = len(sa)
    assert n == len(sb)
    assert sa.records(range(n)) == sb.records(range(n))
    assert np.array_equal(sa.bounds, sb.bounds) and np.array_equal(sa.widths, sb.widths)
    assert np.array_equal(sa.classes, sb.classes) and sa.class_keys == sb.class_keys
    assert sa.rules == sb.rules and sa.origins == sb.origins
    assert ra == rb and list(ka.items()) == list(kb.items())


def test_chunks_read_what_the_file_reads(tmp_path):
    path = _write(tmp_path / "db.geojsonl", _lines(60))
    chunks = list(sequence_chunks(path, batch=7))
    assert len(chunks) == 9 and [c.index for c in chunks] == list(range(0, 60, 7))
    assert sum(c.records for c in chunks) == 60
    serial = _serial(path, batch=7)
    assert_same_read(serial, _parallel(path, batch=7))
    spool, repaired, skipped = serial
    sources = [
        f.source for f in Spool.decode(spool.records(range(len(spool))), spool.rules, spool.origins)
    ]
    assert "feature/9" in sources and "feature/f1" in sources  # no id: the record's index
    assert repaired and skipped["feature without geometry"] and skipped["empty geometry collection"]
    # and inside a box
    box = (14.4, 35.8, 14.42, 35.81)
    assert_same_read(_serial(path, box, 7), _parallel(path, box, 7))


line_kind = st.sampled_from(
    ["box", "point", "bowtie", "none", "park", "bakery", "noid", "rs", "crlf", "blank", "ws"]
    + ["malformed", "array", "far", "fc0", "fc1", "fc2", "lonecr", "badutf8"]
)


def _line(kind, i):
    simple = {"box": "box", "point": "point", "bowtie": "bowtie", "none": "none"}
    if kind in simple:
        return _feature(i, TAGS[0], simple[kind])
    feat = _feature(i, TAGS[0])
    return {
        "park": _feature(i, TAGS[1], "line"),
        "bakery": _feature(i, TAGS[3]),
        "noid": _feature(i, TAGS[2], "point", fid=False),
        "rs": RS + feat,
        "crlf": feat + "\r",
        "blank": "",
        "ws": f" {RS} ",
        "malformed": feat[:-2],
        "array": "[1, 2]",
        "far": feat.replace("14.", "214.", 1),
        "fc0": '{"type": "FeatureCollection", "features": []}',
        "fc1": f'{{"type": "FeatureCollection", "features": [{feat}]}}',
        "fc2": f'{{"type": "FeatureCollection", "features": [{feat}, {feat}]}}',
        "lonecr": feat + "\r" + _feature(i + 1000, TAGS[0]),
        "badutf8": feat[:-1] + ', "name": "\udcff"}',
    }[kind]


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    kinds=st.lists(line_kind, max_size=24),
    batch=st.integers(1, 6),
    box=st.booleans(),
)
def test_any_sequence_reads_alike_in_chunks(tmp_path, kinds, batch, box):
    text = "".join(_line(k, i) + "\n" for i, k in enumerate(kinds))
    path = tmp_path / "db.geojsonl"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    bbox = (14.4, 35.8, 14.43, 35.81) if box else None
    assert_same_read(_serial(str(path), bbox, batch), _parallel(str(path), bbox, batch))


def test_invalid_utf8_raises_where_the_serial_reader_does(tmp_path):
    # a malformed line, then a byte that is not UTF-8 in the same 8 kB text block: the
    # serial reader decodes the block before it parses the line, and says "not UTF-8"; in
    # the next block it parses the line first. Both in one chunk and across two chunks.
    good = _feature(0, TAGS[0])
    pad = "x" * 100
    for where in (100, TEXT_BLOCK - 40, TEXT_BLOCK + 40):
        for batch in (1, 3):
            body = good + "\n" + good[:-3] + "\n"
            filler = _feature(1, {"amenity": "school", "pad": pad})
            lines = body
            while len(lines) < where:
                lines += filler + "\n"
            data = lines.encode() + b'{"bad": "\xff"}\n' + (good + "\n").encode()
            path = tmp_path / f"db{where}-{batch}.geojsonl"
            path.write_bytes(data)
            serial, parallel = _serial(str(path), None, batch), _parallel(str(path), None, batch)
            assert isinstance(serial, str) and serial == parallel


@pytest.fixture(scope="module")
def pool():
    pool = start_pool(2)
    pool.submit(int).result()  # started: the chunks are read there, none here
    yield pool
    pool.shutdown(wait=True)


def test_workers_read_what_the_main_process_reads(tmp_path, pool):
    path = _write(tmp_path / "db.geojsonl", _lines(90))
    assert_same_read(_serial(path, batch=8), _parallel(path, batch=8, pool=pool))
    box = (14.41, 35.8, 14.44, 35.81)
    assert_same_read(_serial(path, box, 8), _parallel(path, box, 8, pool=pool))


def test_several_files_read_alike(tmp_path, pool):
    # two sequences around a FeatureCollection read whole: one spool, tables shared
    first = _write(tmp_path / "a.geojsonl", _lines(30))
    lines = [json.loads(t) for t in (line.strip().strip(RS) for line in _lines(12)) if t]
    whole = tmp_path / "b.geojson"
    whole.write_text(json.dumps({"type": "FeatureCollection", "features": lines}))
    last = _write(tmp_path / "c.geojsons", [RS + line for line in _lines(25)])
    box = (14.4, 35.8, 14.43, 35.81)
    streams = [DatabaseStream([first, str(whole), last], RULES, box) for _ in range(2)]
    serial = _spool_of(streams[0].batches()), streams[0].repaired, streams[0].skipped
    read = sequence_reader(pool, 3, 4)
    parallel = _spool_of(streams[1].batches(read)), streams[1].repaired, streams[1].skipped
    assert_same_read(serial, parallel)
    assert streams[0].count == streams[1].count == len(serial[0]) > 0
    assert len(serial[0].origins) == 3


def test_a_malformed_line_in_the_third_chunk(tmp_path, pool):
    lines = _lines(40)
    lines[19] = '{"type": "Feature", "properties": {"amenity": "school"}'
    path = _write(tmp_path / "db.geojsonl", lines)
    chunks = list(sequence_chunks(path, batch=8))
    assert chunks[2].line <= 20 < chunks[3].line
    message = _serial(path, batch=8)
    assert f"{path}: malformed JSON at line 20 column" in message
    assert _parallel(path, batch=8, pool=pool) == message
    assert pool.submit(int, 3).result() == 3  # the pool still serves


def _malformed(tmp_path):
    """A sequence with a malformed feature in three chunks of 8 records."""
    lines = _lines(40)
    bad = '{"type": "Feature", "properties": {"amenity": "school"}, "geometry": ' \
          '{"type": "LineString", "coordinates": [[14.5, 35.9]]}}'  # fmt: skip
    for i in (3, 21, 37):
        lines[i] = bad
    return _write(tmp_path / "db.geojsonl", lines)


def test_malformed_features_in_several_chunks_are_named_at_once(tmp_path, pool):
    path = _malformed(tmp_path)
    message = _serial(path, batch=8)
    assert message.startswith(f"{path}: 3 problems") and message.count("malformed LineString") == 3
    assert _parallel(path, batch=8, pool=pool) == message
    assert _parallel(path, batch=8) == message  # read here while the workers start


def test_skip_invalid_leaves_them_out_alike(tmp_path, pool):
    path = _malformed(tmp_path)
    streams = [DatabaseStream([path], RULES, skip_invalid=True) for _ in range(2)]
    serial = _spool_of(streams[0].batches())
    parallel = _spool_of(streams[1].batches(sequence_reader(pool, 3, 8)))
    assert_same_read((serial, [], Counter()), (parallel, [], Counter()))
    assert len(streams[0].invalid) == 3 and streams[0].invalid == streams[1].invalid
    assert len({k["airspace"] for k in streams[0].invalid}) == 3
    assert all("malformed LineString" in k["problem"] for k in streams[0].invalid)


def _build(path, out, jobs, monkeypatch, batch=None, stream=None):
    """build_tiled into ``out``; with ``batch``, the workers read the file in chunks."""
    chunks = []
    if batch:
        monkeypatch.setattr(tiled, "WARM_POOL_BYTES", 0)
        monkeypatch.setattr(tiled, "READ_BATCH", batch)
        real = tiled.sequence_reader

        def spy(pool, *args):
            pool.submit(int).result()  # the workers read every chunk
            read = real(pool, *args)
            return lambda *a: (chunks.append(p) or p for p in read(*a))

        monkeypatch.setattr(tiled, "sequence_reader", spy)
    stream = stream or DatabaseStream([path], RULES)
    with open_writers([str(out)], {}) as writers:
        result = tiled.build_tiled(stream, RULES, BuildOptions(), writers=writers, jobs=jobs)
    return result, stream, chunks


def test_a_build_writes_the_same_bytes(tmp_path, monkeypatch):
    path = _write(tmp_path / "db.geojsonl", _lines(80))
    serial, s_stream, _ = _build(path, tmp_path / "serial.geojson", 1, monkeypatch)
    parallel, p_stream, chunks = _build(path, tmp_path / "par.geojson", 2, monkeypatch, 9)
    assert len(chunks) >= 5 and all(isinstance(c, ReadChunk) for c in chunks)
    assert (tmp_path / "serial.geojson").read_bytes() == (tmp_path / "par.geojson").read_bytes()
    assert parallel.features == serial.features == p_stream.count == s_stream.count
    assert p_stream.repaired == s_stream.repaired
    assert list(p_stream.skipped.items()) == list(s_stream.skipped.items())


def test_a_failed_read_writes_nothing(tmp_path, monkeypatch):
    lines = _lines(40)
    lines[30] = "[1, 2]"  # in the fourth chunk
    path = _write(tmp_path / "db.geojsonl", lines)
    with pytest.raises(InputError) as serial:
        _build(path, tmp_path / "serial.geojson", 1, monkeypatch)
    with pytest.raises(InputError) as parallel:
        _build(path, tmp_path / "par.geojson", 2, monkeypatch, 8)
    assert str(parallel.value) == str(serial.value)
    assert "not a GeoJSON Feature" in str(serial.value)
    assert not (tmp_path / "par.geojson").exists()


def test_nothing_restricted_is_said_as_before(tmp_path, monkeypatch):
    lines = [_feature(i, TAGS[3]) for i in range(20)]
    path = _write(tmp_path / "db.geojsonl", lines)
    streams = [DatabaseStream([path], RULES), DatabaseStream([path], RULES)]
    with pytest.raises(InputError) as serial:
        _build(path, tmp_path / "serial.geojson", 1, monkeypatch, stream=streams[0])
    with pytest.raises(InputError) as parallel:
        _build(path, tmp_path / "par.geojson", 2, monkeypatch, 6, stream=streams[1])
    assert str(parallel.value) == str(serial.value)
    assert "no restricted features" in str(serial.value)
    assert list(streams[0].skipped.items()) == list(streams[1].skipped.items())
    assert any(note.startswith(f"all of {path}") for note in streams[1].skipped)
