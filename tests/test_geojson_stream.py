"""Large GeoJSON streamed (zones/geojson_stream.py): a GeoJSON text sequence and a streamed
FeatureCollection give exactly the features the whole-document reader gives, for generated
features of every geometry type, valid or not; what the whole reader refuses, the stream
refuses too, naming the same malformed features, all of them at once."""

from __future__ import annotations

import json
from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.zones.geojson import read_geojson_doc
from alphafence.zones.geojson_stream import RS, iter_geojson
from alphafence.zones.rules import load_rules

RULES = load_rules()
num = st.floats(-200, 200, allow_nan=False, allow_infinity=False)
pos = st.lists(num, min_size=2, max_size=3)
ring = st.lists(pos, min_size=0, max_size=6)
geometry = st.one_of(
    st.builds(lambda c: {"type": "Point", "coordinates": c}, pos),
    st.builds(lambda c: {"type": "LineString", "coordinates": c}, ring),
    st.builds(lambda r: {"type": "Polygon", "coordinates": [r + r[:1]]}, ring),
    st.builds(
        lambda rs: {"type": "MultiPolygon", "coordinates": [[r + r[:1]] for r in rs]},
        st.lists(ring, max_size=3),
    ),
    st.builds(
        lambda g: {"type": "GeometryCollection", "geometries": g},
        st.lists(st.builds(lambda c: {"type": "Point", "coordinates": c}, pos), max_size=2),
    ),
    st.just(None),
    st.just({"type": "Circle", "coordinates": [1, 2]}),
    st.builds(lambda c: {"type": "Polygon", "coordinates": c}, st.lists(ring, max_size=1)),
)
tags = st.sampled_from(
    [{"amenity": "hospital"}, {"aeroway": "aerodrome"}, {"leisure": "park"}, {"shop": "bakery"}]
)
feature = st.builds(
    lambda g, t: {"type": "Feature", "properties": dict(t), "geometry": g}, geometry, tags
)


def _read_whole(path, feats):
    repaired, skipped = [], Counter()
    doc = {"type": "FeatureCollection", "features": feats}
    return read_geojson_doc(path, doc, RULES, repaired, skipped), repaired, skipped


def _read_stream(path):
    repaired, skipped = [], Counter()
    out = [f for b in iter_geojson(path, RULES, repaired, skipped, batch=3) for f in b]
    return out, repaired, skipped


def _errors(exc):
    return getattr(exc, "errors", [exc])


def _faults(exc, leave_out=()):
    """The (feature, problem) pairs an InputError names, one or several."""
    return sorted((e.feature, e.message) for e in _errors(exc) if e.feature not in leave_out)


def _same(a, b):
    assert [f.source for f in a] == [f.source for f in b]
    assert [f.category for f in a] == [f.category for f in b]
    for x, y in zip(a, b):
        assert x.geometry.equals_exact(y.geometry, 0), (x.source, x.geometry, y.geometry)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(feats=st.lists(feature, max_size=8), rs=st.booleans(), collection=st.booleans())
def test_streams_read_what_the_whole_reader_reads(tmp_path, feats, rs, collection):
    if collection:
        path = tmp_path / "db.geojson"
        path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    else:
        path = tmp_path / ("db.geojsons" if rs else "db.geojsonl")
        prefix = RS if rs else ""
        path.write_text("".join(prefix + json.dumps(f) + "\n" for f in feats))
    try:
        whole = _read_whole(str(path), feats)
    except InputError as refused:
        # refused too, naming the file and every malformed feature the whole reader named,
        # but for one difference: GEOS's reader takes a line mixing 2-D and 3-D positions,
        # which shapely's constructor refuses (the stream then reads it, or finds another
        # fault in it); nothing else may differ
        mixed = {e.feature for e in _errors(refused) if "inhomogeneous" in e.message}
        mixed |= {m.replace(" ", "/") for m in mixed}  # named by its source in other faults
        try:
            _read_stream(str(path))
        except InputError as exc:
            assert str(exc).startswith(str(path))
            assert _faults(exc, mixed) == _faults(refused, mixed)
            return
        assert _faults(refused, mixed) == [], refused
        return
    streamed = _read_stream(str(path))
    _same(whole[0], streamed[0])
    assert whole[1] == streamed[1] and whole[2] == streamed[2]


def test_a_malformed_line_is_named(tmp_path):
    path = tmp_path / "db.geojsonl"
    good = json.dumps(
        {
            "type": "Feature",
            "properties": {"amenity": "hospital"},
            "geometry": {"type": "Point", "coordinates": [14.5, 35.9]},
        }
    )
    path.write_text(good + "\n" + good[:-3] + "\n")
    with pytest.raises(InputError, match=r"db.geojsonl: malformed JSON at line 2 column"):
        _read_stream(str(path))
