"""Streamed fence outputs (fencefiles/fence_stream.py): each format round-trips against an
independent parse, the .geojson is byte for byte fence_geojson's, a failure leaves nothing
half-written, and read_fence_file reads every format back as fence_geojson reads GeoJSON."""

from __future__ import annotations

import copy
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import shapely

import alphafence
from alphafence.errors import InputError, MissingDependency
from alphafence.fencefiles import fence_geojson
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.fencefiles.fence_stream import (
    GeoJSONLinesWriter,
    GeoJSONSeqWriter,
    GeoJSONWriter,
    GeoParquetWriter,
    open_writers,
    writer_for,
)
from alphafence.fencefiles.fence_text import FenceFeatures, feature_texts
from alphafence.fencing.outputs import build_meta
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.tile_jobs import fence_rows
from alphafence.mavlink.items import item_count, item_counts
from alphafence.zones.database import read_database

SCENE = Path(alphafence.__file__).parent / "data" / "demo-scene.geojson"
SUFFIXES = (".geojson", ".json", ".geojsonl", ".geojsons", ".geojsonseq", ".parquet")
BATCH = 4


@pytest.fixture(scope="module")
def built(rules):
    """Real fences of the demo scene (alpha and circle), plus three edited to carry what the
    demo has not: a MultiPolygon keep-in with a non-ASCII name, an ED-269 zone, a repair."""
    db = read_database([SCENE], rules)
    fences = build_fences(db.features, rules, BuildOptions()).fences
    fences += build_fences(db.features, rules, BuildOptions(method="circle")).fences
    first = fences[0]
    two = shapely.MultiPolygon([shapely.box(-60, -60, -10, -10), shapely.box(10, 10, 70, 40)])
    fences.append(
        replace(first, site_id="zone/Ħ-1", name="Ħal Far ✈ “keep in”", kind="keep_in", local=two)
    )
    zone = {"identifier": "MT-1", "restriction": "PROHIBITED", "reason": ["SENSITIVE"]}
    fences.append(replace(first, site_id="zone/MT-1", alt_min_m=0, alt_max_m=120, properties=zone))
    fences.append(replace(first, site_id="hospital/way/9", repaired=True))
    meta = build_meta(db, rules, BuildOptions())
    return fences, meta, fence_geojson.fences_geojson(fences, meta)


def _write(paths, meta, features, batch=BATCH):
    with open_writers(paths, meta) as writers:
        encoders = writers.encoders()
        for i in range(0, len(features), batch):
            writers.write([encode(features[i : i + batch]) for encode in encoders])
    return writers


def _same_fence(a, b):
    assert (a.site_id, a.kind, a.name, a.category) == (b.site_id, b.kind, b.name, b.category)
    assert (a.margin_m, a.alt_min_m, a.alt_max_m, a.circle) == (
        b.margin_m,
        b.alt_min_m,
        b.alt_max_m,
        b.circle,
    )
    assert a.geometry.equals_exact(b.geometry, 0)
    assert a.properties == b.properties


def test_the_streamed_geojson_is_fence_geojsons_text_byte_for_byte(built, tmp_path):
    fences, meta, doc = built
    for batch in (1, BATCH, len(fences)):
        out = tmp_path / f"b{batch}.geojson"
        _write([out], meta, doc["features"], batch)
        assert out.read_bytes() == fence_geojson.dumps(doc).encode("utf-8")
    # no meta: no "alphafence" member, as fence_geojson writes it; no fences: an empty list
    _write([tmp_path / "plain.json"], {}, doc["features"])
    plain = fence_geojson.dumps(fence_geojson.fences_geojson(fences))
    assert (tmp_path / "plain.json").read_text(encoding="utf-8") == plain
    _write([tmp_path / "none.geojson"], meta, [])
    empty = fence_geojson.dumps(fence_geojson.fences_geojson([], meta))
    assert (tmp_path / "none.geojson").read_text(encoding="utf-8") == empty


def test_sequences_are_one_feature_per_record_with_the_meta_on_the_first(built, tmp_path):
    _, meta, doc = built
    paths = [tmp_path / f"f{s}" for s in (".geojsonl", ".geojsons", ".geojsonseq")]
    _write(paths, meta, doc["features"])
    for path in paths:
        data = path.read_bytes()
        rs = path.suffix != ".geojsonl"
        assert data.startswith(b"\x1e{") == rs and data.endswith(b"}\n")
        lines = data.decode("utf-8").split("\n")[:-1]
        assert len(lines) == len(doc["features"])
        records = []
        for line in lines:
            assert line.startswith("\x1e") == rs and "\x1e" not in line[1:]
            records.append(json.loads(line.lstrip("\x1e")))
        assert all(r["type"] == "Feature" for r in records)
        first = records[0]
        assert first.pop("generator") == doc["generator"] and first.pop("alphafence") == meta
        assert records == doc["features"]  # exactly the features, in order
    # an empty build: an empty file
    _write([tmp_path / "none.geojsonl"], meta, [])
    assert (tmp_path / "none.geojsonl").read_bytes() == b""


def test_geoparquet_round_trip_and_valid_geo_metadata(built, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    _, meta, doc = built
    features = doc["features"]
    path = tmp_path / "fences.parquet"
    writers = _write([path], meta, features)
    assert writers[0].records == len(features)
    table = pq.read_table(path)
    assert table.num_rows == len(features)
    rows = table.to_pylist()
    geoms = shapely.from_wkb([r["geometry"] for r in rows])
    for row, geom, feat in zip(rows, geoms, features):
        assert geom.equals_exact(shapely.geometry.shape(feat["geometry"]), 0)
        props = dict(feat["properties"])
        for name in ("site_id", "name", "category", "kind", "method", "margin_m", "vertices"):
            assert row[name] == props.pop(name)
        for name in ("alt_min_m", "alt_max_m", "area_m2", "sources"):
            assert row[name] == props.pop(name)
        assert (json.loads(row["extra"]) if row["extra"] else {}) == props
    extras = [json.loads(r["extra"]) for r in rows if r["extra"]]
    assert sum(e.get("zone", {}).get("identifier") == "MT-1" for e in extras) == 1
    assert sum("radius_m" in e for e in extras) == len(built[0]) // 2 - 1  # the circles

    # the GeoParquet 1.1 file metadata (https://geoparquet.org/releases/v1.1.0/)
    metadata = pq.read_schema(path).metadata
    geo = json.loads(metadata[b"geo"])
    assert geo["version"] == "1.1.0" and geo["primary_column"] == "geometry"
    assert set(geo["columns"]) == {"geometry"}
    column = geo["columns"]["geometry"]
    assert column["encoding"] == "WKB" and "crs" not in column  # absent crs: OGC:CRS84
    types = column["geometry_types"]
    assert len(types) == len(set(types))
    assert set(types) == {g.geom_type for g in geoms} == {"Polygon", "MultiPolygon"}
    assert column["bbox"] == list(shapely.total_bounds(geoms))
    assert json.loads(metadata[b"alphafence"]) == meta
    schema = pq.ParquetFile(path).schema  # the geometry: a top-level BYTE_ARRAY column
    assert schema.column(schema.names.index("geometry")).physical_type == "BYTE_ARRAY"
    assert schema.column(schema.names.index("geometry")).max_repetition_level == 0


def test_geoparquet_is_written_in_row_groups_as_batches_arrive(built, tmp_path, monkeypatch):
    pq = pytest.importorskip("pyarrow.parquet")
    _, meta, doc = built
    monkeypatch.setattr(GeoParquetWriter, "row_group_rows", 10)
    path = tmp_path / "groups.parquet"
    _write([path], meta, doc["features"], batch=3)
    metadata = pq.ParquetFile(path).metadata
    sizes = [metadata.row_group(i).num_rows for i in range(metadata.num_row_groups)]
    assert sum(sizes) == len(doc["features"]) and len(sizes) > 1
    assert all(n >= 10 for n in sizes[:-1])  # small batches gathered into row groups


def test_encoded_batches_travel_from_worker_processes(built, tmp_path):
    _, meta, doc = built
    features = doc["features"]
    paths = [tmp_path / f"w{s}" for s in SUFFIXES if s != ".parquet" or _has_pyarrow()]
    writers = open_writers(paths, meta)
    batches = [features[i : i + BATCH] for i in range(0, len(features), BATCH)]
    with writers, ProcessPoolExecutor(max_workers=2) as pool:
        # workers encode, this process writes, in order
        jobs = [[pool.submit(e, b) for e in writers.encoders()] for b in batches]
        for job in jobs:
            writers.write([j.result() for j in job])
    reference = tmp_path / "reference.geojson"
    reference.write_text(fence_geojson.dumps(doc), encoding="utf-8")
    expected = fence_geojson.read_fences(reference)
    for path in paths:
        got = read_fence_file(path)
        assert len(got) == len(expected), path
        for a, b in zip(got, expected):
            _same_fence(a, b)


def _encodings(features):
    out = [cls.encode(features) for cls in (GeoJSONWriter, GeoJSONLinesWriter, GeoJSONSeqWriter)]
    if _has_pyarrow():
        table, types, bounds = GeoParquetWriter.encode(features)
        out.append((table.to_pylist(), types, bounds))
    return out


def test_features_made_together_are_written_as_their_dicts_are(built):
    """fence_features' Features keep their coordinates as arrays, which the writers turn into
    text and shapes without reading the dicts: the bytes are those the dicts give, for simple
    polygons, a batch with a MultiPolygon (parts and rings taken apart), a Feature whose
    geometry was replaced, and properties holding the text the encoder cuts at."""
    fences = built[0]
    simple = [f for f in fences if f.local.geom_type == "Polygon"]
    assert len(simple) < len(fences)
    for batch in (fences, simple, fences[:1]):
        features = fence_geojson.fence_features(batch)
        assert isinstance(features, FenceFeatures)
        assert _encodings(features) == _encodings(copy.deepcopy(list(features)))
    features = fence_geojson.fence_features(fences)
    features[3]["properties"]["zone"] = {"a": 1, "geometry": "\0"}
    assert _encodings(features) == _encodings(copy.deepcopy(list(features)))
    assert '"zone":{"a":1,"geometry":"\\u0000"}' in feature_texts(features)[3]
    moved = copy.deepcopy(features[2]["geometry"])
    moved["coordinates"][0][0] = moved["coordinates"][0][-1] = [14.25, 35.75]
    features[2] = {**features[2], "geometry": moved}
    assert _encodings(features) == _encodings(copy.deepcopy(list(features)))
    assert "[14.25,35.75]" in feature_texts(features)[2]


def test_coordinates_are_written_as_repr_writes_them():
    """The coordinates' text made from 1e-8-degree integers is ``repr``'s, digit for digit;
    numbers it is not made for (below 1e-4, not a whole number of 1e-8) are left to json."""
    rng = np.random.default_rng(7)
    edges = [1e-4, -1e-4, 0.00012345, 12.5, 180.0, -180.0, 99.99999999, 1.0, 9999.99999999]
    values = np.concatenate([rng.uniform(-180, 180, 3000), rng.uniform(-1, 1, 500), edges])
    values = [round(v, 8) for v in values.tolist()]
    values += [round(v, int(d)) for v, d in zip(rng.uniform(-99, 99, 500), rng.integers(0, 8, 500))]
    for extra in ([], [5e-05], [0.0], [123.456789012]):
        xy = values + extra + [1.5] * ((len(values) + len(extra)) % 2)
        ring = [xy[i : i + 2] for i in range(0, len(xy), 2)]
        ring.append(ring[0])
        geometry = {"type": "Polygon", "coordinates": [ring]}
        feature = {"type": "Feature", "properties": {"name": "ring"}, "geometry": geometry}
        index = np.array([0])
        features = FenceFeatures(
            [feature], None, np.array(ring), np.array([len(ring)]), index, index
        )
        assert feature_texts(features) == [json.dumps(feature, separators=(",", ":"))]


def test_fence_rows_numbers_are_each_fences_own(built):
    """Vertices, areas and fence items counted for all fences at once are each fence's own
    (Fence.vertices, Fence.area_m2, item_count) for circles, polygons with and without holes,
    multipolygons, empty ones, keep-out, keep-in and warning layers."""
    fences = list(built[0])
    holed = shapely.Polygon([(0, 0), (90, 0), (90, 90), (0, 90)], [[(10, 10), (20, 10), (20, 30)]])
    for kind in ("keep_out", "keep_in", "warning"):
        for local in (holed, shapely.MultiPolygon([holed, shapely.box(200, 0, 230, 40)])):
            fences.append(replace(fences[0], kind=kind, local=local))
    fences.append(replace(fences[0], local=shapely.MultiPolygon()))
    kinds = {(f.kind, f.circle is not None, f.local.geom_type) for f in fences}
    assert len(kinds) >= 8
    assert item_counts(fences) == [item_count(f) for f in fences]
    vertices, areas = fence_geojson.fence_numbers(fences)
    assert vertices == [f.vertices for f in fences]
    assert areas == [f.area_m2 for f in fences]
    rows = fence_rows(fences)
    assert [r[2:4] + r[7:] for r in rows] == [
        (f.vertices, f.area_m2, item_count(f), f.growth) for f in fences
    ]


def _has_pyarrow():
    try:
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        return False
    return True


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_an_exception_mid_write_leaves_the_old_file_and_no_temp(built, tmp_path, suffix):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow.parquet")
    _, meta, doc = built
    path = tmp_path / f"fences{suffix}"
    path.write_bytes(b"the previous build\n")
    cls = writer_for(path)
    with pytest.raises(RuntimeError, match="tile 3 failed"):
        with cls(path, meta) as writer:
            writer.write(cls.encode(doc["features"][:BATCH]))
            assert _listing(tmp_path) == sorted([path.name, writer.tmp.name])
            raise RuntimeError("tile 3 failed")
    assert path.read_bytes() == b"the previous build\n"
    assert _listing(tmp_path) == [path.name]
    # and a new path is not created at all
    with pytest.raises(KeyboardInterrupt):
        with cls(tmp_path / f"new{suffix}", meta):
            raise KeyboardInterrupt
    assert _listing(tmp_path) == [path.name]


def test_several_outputs_are_committed_all_or_nothing(built, tmp_path, monkeypatch):
    _, meta, doc = built
    a, b = tmp_path / "a.geojson", tmp_path / "b.geojsonl"
    a.write_text("old a\n")
    writers = open_writers([a, b], meta)
    writers.write([enc(doc["features"]) for enc in writers.encoders()])

    def disk_full(self):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(type(writers[1]), "_end", disk_full)  # the second fails to finish
    with pytest.raises(OSError, match="No space left"):
        writers.commit()
    assert a.read_text() == "old a\n" and not b.exists()
    assert _listing(tmp_path) == ["a.geojson"]
    # an output that cannot be opened: the others opened before it are removed
    (tmp_path / "file").write_text("")
    with pytest.raises(OSError):
        open_writers([tmp_path / "c.geojson", tmp_path / "file" / "d.geojson"], meta)
    assert _listing(tmp_path) == ["a.geojson", "file"]


def test_unknown_suffix_and_a_path_named_twice_are_one_line(tmp_path):
    with pytest.raises(InputError) as err:
        writer_for(tmp_path / "fences.kml")
    msg = str(err.value)
    assert msg.startswith(str(tmp_path / "fences.kml")) and "\n" not in msg
    assert "'.kml'" in msg and ".geojsonl" in msg and ".parquet" in msg
    with pytest.raises(InputError, match="no suffix|'\\(none\\)'"):
        writer_for(tmp_path / "fences")
    with pytest.raises(InputError, match="named twice"):
        open_writers([tmp_path / "x.geojson", tmp_path / "." / "x.geojson"], {})
    assert _listing(tmp_path) == []


def test_missing_pyarrow_is_one_line_and_leaves_no_temp(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    with pytest.raises(MissingDependency) as err:
        open_writers([tmp_path / "a.geojson", tmp_path / "fences.parquet"], {})
    msg = str(err.value)
    assert (
        msg == "writing GeoParquet needs pyarrow 17.0 or later: in the AlphaFence checkout: "
        "pip install '.[parquet]' (or everything: pip install -e '.[all]')"
    )
    assert _listing(tmp_path) == []
    (tmp_path / "in.parquet").write_bytes(b"PAR1")
    with pytest.raises(MissingDependency, match="reading .*in.parquet needs pyarrow"):
        read_fence_file(tmp_path / "in.parquet")


def test_sequences_from_other_tools_are_read(built, tmp_path):
    _, _, doc = built
    features = doc["features"]
    plain = "".join(json.dumps(f) + "\r\n" for f in features)  # GDAL-style, CRLF, no meta
    (tmp_path / "gdal.geojsonl").write_text(plain, encoding="utf-8")
    fc = {"type": "FeatureCollection", "features": features[1:]}  # a FeatureCollection record
    seq = "\x1e" + json.dumps(features[0]) + "\n\x1e" + json.dumps(fc) + "\n\x1e\n"
    (tmp_path / "mixed.txt").write_text(seq, encoding="utf-8")  # told by its first byte
    reference = tmp_path / "reference.geojson"
    reference.write_text(fence_geojson.dumps(doc), encoding="utf-8")
    expected = fence_geojson.read_fences(reference)
    for name in ("gdal.geojsonl", "mixed.txt"):
        got = read_fence_file(tmp_path / name)
        assert len(got) == len(expected)
        for a, b in zip(got, expected):
            _same_fence(a, b)


@pytest.mark.parametrize(
    ("text", "fault"),
    [
        (
            '{"type":"Feature","properties":{"kind":"keep_out"},"geometry":{"type":"Polygon"',
            "malformed JSON",
        ),
        ('{"type":"Point","coordinates":[1,2]}', "not a GeoJSON Feature ('Point')"),
        (
            '{"type":"Feature","properties":{"site_id":"s","kind":"nope"},"geometry":null}',
            "kind must be",
        ),
        (
            '{"type":"Feature","properties":{"site_id":"s","kind":"warning"},"geometry":{"type":"Point","coordinates":[1,2]}}',
            "not Point",
        ),
        (
            '{"type":"Feature","properties":{"site_id":"s","kind":"warning"},"geometry":{"type":"Polygon","coordinates":[[[0,0],[200,0],[0,1],[0,0]]]}}',
            "out of range",
        ),
    ],
)
def test_a_bad_record_is_one_line_naming_it(built, tmp_path, text, fault):
    _, _, doc = built
    good = json.dumps(doc["features"][0])
    path = tmp_path / "bad.geojsons"
    path.write_text(f"\x1e{good}\n\x1e{text}\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_fence_file(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: record 1") and fault in msg and "\n" not in msg


def test_a_parquet_file_that_is_not_geoparquet_is_one_line(tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    plain = tmp_path / "plain.parquet"
    pq.write_table(pa.table({"kind": ["keep_out"]}), plain)
    with pytest.raises(InputError, match="not GeoParquet: no 'geo' file metadata"):
        read_fence_file(plain)
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"not parquet at all")
    with pytest.raises(InputError, match="not a Parquet file") as err:
        read_fence_file(junk)
    assert "\n" not in str(err.value)
    assert not os.path.exists(tmp_path / "missing.parquet")
    with pytest.raises(InputError, match="no such file"):
        read_fence_file(tmp_path / "missing.parquet")
