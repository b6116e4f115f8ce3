"""The update store's middle (``updating/middle.py``) on a small hand-made extract: what it
keeps of the extract, which objects a change names as touched (the ways on a moved node, the
relations of those ways, nothing else), how the store follows the change, and the small
extract written for the build's reader. Each expectation is read off the extract below."""

from __future__ import annotations

import json
import sqlite3

import osmium
import pytest
from osmium.osm import mutable

from alphafence.errors import InputError
from alphafence.updating.middle import (
    Changes,
    apply_changes,
    keyed,
    load_middle,
    read_changes,
    write_extract,
)

KEYS = ("amenity", "aeroway")
# node id -> (lon, lat); 11 is a keyed point, 12 an untagged node no way uses
PLACES = {n: (14.0 + n / 1000, 35.0 + n / 2000) for n in range(1, 13)}
PRISON = {"amenity": "prison", "name": "P"}
HOSPITAL = {"type": "multipolygon", "amenity": "hospital"}


def write_osm(path, nodes=(), ways=(), relations=()):
    """An OpenStreetMap file: ``nodes`` as ``(id, (lon, lat), tags, deleted)``, ``ways`` as
    ``(id, refs, tags, deleted)``, ``relations`` as ``(id, members, tags, deleted)``."""
    with osmium.SimpleWriter(str(path)) as w:
        for i, loc, tags, gone in nodes:
            w.add_node(mutable.Node(id=i, location=loc, tags=tags, version=2, visible=not gone))
        for i, refs, tags, gone in ways:
            w.add_way(mutable.Way(id=i, nodes=refs, tags=tags, version=2, visible=not gone))
        for i, members, tags, gone in relations:
            w.add_relation(mutable.Relation(id=i, members=members, tags=tags, version=2,
                                            visible=not gone))  # fmt: skip


@pytest.fixture
def db(tmp_path):
    """The middle of: way 100 a prison (nodes 1-4), ways 101 and 102 the untagged members of
    hospital relation 200 (nodes 5-7, 7-9), way 103 untagged and in no relation (9, 10), way
    104 tagged with no rule's key (1, 5); node 11 a keyed point, node 12 alone."""
    nodes = [(n, loc, {"amenity": "clinic"} if n == 11 else {}, False)
             for n, loc in PLACES.items()]  # fmt: skip
    ways = [(100, [1, 2, 3, 4, 1], PRISON, False), (101, [5, 6, 7], {}, False),
            (102, [7, 8, 9, 7], {}, False), (103, [9, 10], {}, False),
            (104, [1, 5], {"highway": "path"}, False)]  # fmt: skip
    rels = [
        (200, [("w", 101, "outer"), ("w", 102, "outer"), ("n", 11, "")], HOSPITAL, False),
        (201, [("w", 103, "outer")], {"type": "multipolygon", "natural": "wood"}, False),
    ]
    path = tmp_path / "extract.osm"
    write_osm(path, nodes, ways, rels)
    con = sqlite3.connect(":memory:")
    seen = []
    load_middle(con, path, KEYS, seen.append)
    assert seen == []  # fewer nodes than a progress step
    return con


def table(con, sql):
    return sorted(con.execute(sql).fetchall())


def changes_of(tmp_path, name="c.osc", **objects):
    path = tmp_path / name
    write_osm(path, **objects)
    return read_changes([path])


def test_keyed_is_any_key_of_a_rule():
    assert keyed({"amenity": "prison"}, KEYS) and keyed({"x": "1", "aeroway": "a"}, KEYS)
    assert not keyed({"name": "amenity"}, KEYS) and not keyed({}, KEYS)
    assert not keyed({"amenity": "x"}, ())


def test_the_middle_keeps_places_ways_and_keyed_relations(db):
    assert table(db, "SELECT id, x, y FROM nodes") == [
        (n, round(lon * 1e7), round(lat * 1e7)) for n, (lon, lat) in sorted(PLACES.items())
    ]
    ways = {w: (json.loads(t) if t else None) for w, _, t in table(db, "SELECT * FROM ways")}
    assert ways == {100: PRISON, 101: None, 102: None, 103: None, 104: None}
    assert table(db, "SELECT id FROM ways WHERE tags IS NULL") == [(101,), (102,), (103,), (104,)]
    assert [r for r, *_ in table(db, "SELECT * FROM rels")] == [200]  # 201: no rule's key
    assert table(db, "SELECT id, nodes FROM ways WHERE id = 102") == [
        (102, bytes.fromhex("0700000000000000080000000000000009000000000000000700000000000000"))
    ]  # node ids as 8-byte little-endian integers, whatever the machine's own
    members, tags = db.execute("SELECT members, tags FROM rels WHERE id = 200").fetchone()
    assert json.loads(tags) == HOSPITAL
    assert json.loads(members) == [["w", 101, "outer"], ["w", 102, "outer"], ["n", 11, ""]]
    assert table(db, "SELECT * FROM way_rels") == [(101, 200), (102, 200)]
    assert table(db, "SELECT * FROM node_ways") == sorted(
        [(n, 100) for n in (1, 2, 3, 4)] + [(n, 101) for n in (5, 6, 7)]
        + [(n, 102) for n in (7, 8, 9)]
    )  # fmt: skip


def test_a_big_extract_reports_its_progress(tmp_path):
    path = tmp_path / "big.osm.pbf"
    write_osm(path, [(n, (14.0, 35.0), {}, False) for n in range(1, 120_001)])
    seen = []
    load_middle(sqlite3.connect(":memory:"), path, KEYS, seen.append)
    assert seen == [50_000, 100_000]


def test_change_files_keep_the_last_version_of_each_object(tmp_path):
    a = tmp_path / "a.osc"
    write_osm(
        a,
        [(2, (14.5, 35.5), {}, False), (3, (14.6, 35.6), {"amenity": "x"}, False)],
        [(100, [1, 2], PRISON, False)],
        [(200, [("w", 101, "outer")], HOSPITAL, False)],
    )
    b = tmp_path / "b.osc.gz"
    write_osm(b, [(2, (14.7, 35.7), {}, False), (4, (14.0, 35.0), {}, True)],
              [(100, [], {}, True)], [(200, [], {}, True)])  # fmt: skip
    got = read_changes([a, b])
    assert got.files == [str(a), str(b)] and len(got) == 5
    assert got.nodes == {
        2: (147_000_000, 357_000_000, {}),
        3: (146_000_000, 356_000_000, {"amenity": "x"}),
        4: None,
    }
    assert got.ways == {100: None} and got.relations == {200: None}
    assert read_changes([b, a]).ways == {100: ([1, 2], PRISON)}
    assert read_changes([b, a]).relations == {200: ([("w", 101, "outer")], HOSPITAL)}


def test_change_files_read_badly_are_one_line(tmp_path):
    cases = [
        (tmp_path / "x.osm", "not an OpenStreetMap change file (.osc, .osc.gz)"),
        (tmp_path / "gone.osc", "no such file"),
    ]
    bad = tmp_path / "bad.osc"
    bad.write_text("<osmChange><node id='1' lat='x'", encoding="utf-8")
    for path, message in cases:
        with pytest.raises(InputError) as caught:
            read_changes([path])
        assert str(caught.value) == f"{path}: {message}"
    with pytest.raises(InputError) as caught:
        read_changes([bad])
    assert str(caught.value).startswith(f"{bad}: not a readable change file (")
    good = tmp_path / "good.osc"
    write_osm(good, [(1, (14.0, 35.0), {}, False), (2, (14.0, 35.0), {}, False)])
    calls = []
    read_changes([good], stop=lambda: calls.append(1))
    assert calls == [1, 1]  # asked after every object


@pytest.mark.parametrize(
    "moved, ways, relations",
    [
        (2, {100}, set()),  # the prison's node (104, on it too, has no rule's key)
        (6, {101}, {200}),  # a member of the hospital: its relation
        (7, {101, 102}, {200}),
        (10, set(), set()),  # on an untagged way of no keyed relation: nothing
        (12, set(), set()),
    ],
)
def test_a_moved_node_touches_the_ways_and_relations_it_shapes(db, tmp_path, moved, ways,
                                                               relations):  # fmt: skip
    change = changes_of(tmp_path, nodes=[(moved, (14.9, 35.9), {}, False)])
    touched = apply_changes(db, change, KEYS)
    assert touched == {"node": {moved}, "way": ways, "relation": relations}
    assert db.execute("SELECT x, y FROM nodes WHERE id = ?", (moved,)).fetchone() == (
        149_000_000, 359_000_000)  # fmt: skip


def test_a_deleted_node_leaves_the_store(db, tmp_path):
    touched = apply_changes(db, changes_of(tmp_path, nodes=[(3, (0, 0), {}, True)]), KEYS)
    assert touched["way"] == {100}
    assert db.execute("SELECT 1 FROM nodes WHERE id = 3").fetchone() is None
    assert db.execute("SELECT 1 FROM nodes WHERE id = 2").fetchone() == (1,)


def test_a_way_deleted_retagged_or_redrawn(db, tmp_path):
    change = changes_of(tmp_path, ways=[(100, [], {}, True), (103, [9, 10, 12, 9], PRISON, False),
                                        (101, [5, 6, 12], {}, False),
                                        (104, [1, 2], {"highway": "track"}, False)])  # fmt: skip
    touched = apply_changes(db, change, KEYS)
    assert touched == {"node": set(), "way": {100, 101, 103, 104}, "relation": {200}}
    ways = {w: (t and json.loads(t)) for w, _, t in table(db, "SELECT * FROM ways")}
    assert ways == {101: None, 102: None, 103: PRISON, 104: None}
    links = table(db, "SELECT * FROM node_ways")
    assert not [x for x in links if x[1] in (100, 104)]
    assert [n for n, w in links if w == 103] == [9, 10, 12]  # newly keyed: its nodes followed
    assert [n for n, w in links if w == 101] == [5, 6, 12]  # a relation's member: followed
    assert [n for n, w in links if w == 102] == [7, 8, 9]  # untouched
    # then a node of the newly keyed way moves: the way is named
    again = apply_changes(db, changes_of(tmp_path, "d.osc", nodes=[(12, (1, 1), {}, False)]), KEYS)
    assert again["way"] == {101, 103} and again["relation"] == {200}


def test_relations_added_retagged_and_deleted(db, tmp_path):
    members = [("w", 103, "outer")]
    change = changes_of(tmp_path, relations=[(201, members, {"aeroway": "aerodrome"}, False)])
    assert apply_changes(db, change, KEYS)["relation"] == {201}
    assert (103, 201) in table(db, "SELECT * FROM way_rels")
    assert [n for n, w in table(db, "SELECT * FROM node_ways") if w == 103] == [9, 10]
    gone = changes_of(
        tmp_path,
        "d.osc",
        relations=[(200, [], {}, True), (201, members, {"natural": "wood"}, False)],
    )
    assert apply_changes(db, gone, KEYS)["relation"] == {200, 201}
    assert table(db, "SELECT id FROM rels") == [] and table(db, "SELECT * FROM way_rels") == []


def read_back(path):
    """An OpenStreetMap file's objects: ``(nodes, ways, relations)`` as plain values."""
    nodes, ways, rels = {}, {}, {}
    for obj in osmium.FileProcessor(str(path)):
        tags = dict(obj.tags)
        if obj.is_node():
            nodes[obj.id] = (round(obj.location.lon, 7), round(obj.location.lat, 7), tags)
        elif obj.is_way():
            ways[obj.id] = ([n.ref for n in obj.nodes], tags)
        else:
            rels[obj.id] = ([(m.type, m.ref, m.role) for m in obj.members], tags)
    return nodes, ways, rels


def test_the_extract_holds_what_the_touched_features_are_made_of(db, tmp_path):
    change = changes_of(tmp_path, nodes=[(6, (14.25, 35.25), {}, False),
                                         (11, (14.011, 35.0055), {"amenity": "clinic"}, False),
                                         (12, (14.3, 35.3), {"amenity": "school"}, False),
                                         (10, (14.4, 35.4), {}, False)])  # fmt: skip
    touched = apply_changes(db, change, KEYS)
    out = tmp_path / "mini.osm"
    write_extract(db, touched, change, out)
    nodes, ways, rels = read_back(out)
    assert rels == {200: ([("w", 101, "outer"), ("w", 102, "outer"), ("n", 11, "")], HOSPITAL)}
    assert ways == {101: ([5, 6, 7], {}), 102: ([7, 8, 9, 7], {})}
    place = {n: (round(lon, 7), round(lat, 7), {}) for n, (lon, lat) in PLACES.items()}
    want = {n: place[n] for n in (5, 7, 8, 9)}
    want[6] = (14.25, 35.25, {})
    want[11] = (14.011, 35.0055, {"amenity": "clinic"})
    want[12] = (14.3, 35.3, {"amenity": "school"})
    assert nodes == want  # 10 is untagged and on no touched way: not written


def test_the_extract_leaves_out_what_the_change_removed(db, tmp_path):
    change = changes_of(tmp_path, ways=[(100, [], {}, True), (102, [7, 8, 7], {}, False)],
                        relations=[(200, [("w", 102, "outer")], HOSPITAL, False)])  # fmt: skip
    touched = apply_changes(db, change, KEYS)
    assert touched["way"] == {100, 102} and touched["relation"] == {200}
    out = tmp_path / "mini.osm.pbf"
    write_extract(db, touched, change, out)
    nodes, ways, rels = read_back(out)
    assert rels == {200: ([("w", 102, "outer")], HOSPITAL)}
    assert ways == {102: ([7, 8, 7], {})} and sorted(nodes) == [7, 8]


def test_an_empty_change_touches_nothing(db, tmp_path):
    before = {t: table(db, f"SELECT * FROM {t}") for t in ("nodes", "ways", "rels", "node_ways",
                                                            "way_rels")}  # fmt: skip
    assert apply_changes(db, Changes(), KEYS) == {"node": set(), "way": set(), "relation": set()}
    assert before == {t: table(db, f"SELECT * FROM {t}") for t in before}


def test_a_keyed_way_goes_into_the_extract_with_its_tags_and_nodes(db, tmp_path):
    change = changes_of(tmp_path, nodes=[(2, (14.2, 35.2), {}, False)],
                        relations=[(200, [("w", 101, "outer"), ("n", 103, "")], HOSPITAL,
                                    False)])  # fmt: skip
    touched = apply_changes(db, change, KEYS)
    assert touched == {"node": {2}, "way": {100}, "relation": {200}}
    out = tmp_path / "mini.osm"
    write_extract(db, touched, change, out)
    nodes, ways, rels = read_back(out)
    # the node member 103 is no way: way 103 stays out
    assert ways == {100: ([1, 2, 3, 4, 1], PRISON), 101: ([5, 6, 7], {})}
    assert rels == {200: ([("w", 101, "outer"), ("n", 103, "")], HOSPITAL)}
    assert sorted(nodes) == [1, 2, 3, 4, 5, 6, 7] and nodes[2] == (14.2, 35.2, {})


def test_changes_of_many_objects_are_looked_up_in_full(tmp_path):
    """More ids than one SQL lookup takes (500): every chunk is looked up, none twice."""
    n = 1234
    nodes = [(i, (14.0 + i / 1e5, 35.0), {}, False) for i in range(1, n + 1)]
    ways = [(10_000 + i, [i], {"amenity": "bench"}, False) for i in range(1, n + 1)]  # one each
    path = tmp_path / "many.osm"
    write_osm(path, nodes, ways)
    con = sqlite3.connect(":memory:")
    load_middle(con, path, KEYS)
    change = changes_of(tmp_path, nodes=[(i, (15.0, 36.0), {}, False) for i in range(1, n + 1)])
    touched = apply_changes(con, change, KEYS)
    assert touched["way"] == {10_000 + i for i in range(1, n + 1)}
    out = tmp_path / "mini.osm"
    write_extract(con, touched, change, out)
    got, ways_out, _ = read_back(out)
    assert sorted(got) == list(range(1, n + 1)) and len(ways_out) == n
    assert {v[:2] for v in got.values()} == {(15.0, 36.0)}
