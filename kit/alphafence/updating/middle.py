"""An OpenStreetMap extract's nodes and ways kept in the update store, and its changes
(``.osc``/``.osc.gz``) applied to them.

A change file names what changed, not what it moves: a node moved is a node, not the hospital
whose outline it is on; a way newly tagged ``amenity=prison`` comes with its node ids but not
their places. The store keeps what answers both (as osm2pgsql's middle does): every node's
place, every way's node ids, and for the objects carrying a key some rule looks at, their
tags and the ways and nodes they are made of. :func:`apply_changes` updates it and names
every object whose feature may have changed; :func:`write_extract` writes those objects, with
everything they are made of, as a small extract that the build's own reader reads.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from alphafence.errors import InputError

MIDDLE = """
CREATE TABLE IF NOT EXISTS nodes (id INTEGER PRIMARY KEY, x INTEGER NOT NULL, y INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS ways (id INTEGER PRIMARY KEY, nodes BLOB NOT NULL, tags TEXT);
CREATE TABLE IF NOT EXISTS rels (id INTEGER PRIMARY KEY, members TEXT NOT NULL, tags TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS node_ways (node INTEGER NOT NULL, way INTEGER NOT NULL,
    UNIQUE (node, way));
CREATE TABLE IF NOT EXISTS way_rels (way INTEGER NOT NULL, rel INTEGER NOT NULL,
    UNIQUE (way, rel));
"""
BATCH = 50_000


def keyed(tags, keys) -> bool:
    """Whether an object carries a key some rule looks at (what the build's reader assembles).

    Examples
    --------
    >>> keyed({"amenity": "prison", "name": "X"}, ("amenity",)), keyed({"name": "X"}, ("amenity",))
    (True, False)
    """
    return any(k in tags for k in keys)


def _blob(refs):
    return np.asarray(refs, dtype="<i8").tobytes()


def _refs(blob):
    return np.frombuffer(blob, dtype="<i8").tolist()


def load_middle(db, path, keys, progress=None):
    """Keep the extract ``path``'s nodes, ways and keyed relations in the store ``db``.

    Parameters
    ----------
    db : sqlite3.Connection
    path : str
    keys : tuple of str
        The rules' keys.
    progress : callable, optional
        ``progress(nodes)``, every 50,000 nodes kept.
    """
    import osmium

    for statement in MIDDLE.split(";"):  # not executescript: it would end the transaction
        if statement.strip():
            db.execute(statement)
    nodes, ways, rels, kept = [], [], [], 0
    kinds = osmium.osm.NODE | osmium.osm.WAY | osmium.osm.RELATION
    for obj in osmium.FileProcessor(str(path), kinds):
        if obj.is_node():
            loc = obj.location
            if loc.valid():
                nodes.append((obj.id, loc.x, loc.y))
                if len(nodes) >= BATCH:
                    db.executemany("INSERT OR REPLACE INTO nodes VALUES (?, ?, ?)", nodes)
                    kept, nodes = kept + len(nodes), []
                    if progress:
                        progress(kept)
        elif obj.is_way():
            tags = obj.tags
            tags = dict(tags) if len(tags) and keyed(tags, keys) else None
            ways.append((obj.id, [n.ref for n in obj.nodes], tags))
        elif len(obj.tags) and keyed(obj.tags, keys):
            members = [(m.type, m.ref, m.role) for m in obj.members]
            rels.append((obj.id, members, dict(obj.tags)))
    db.executemany("INSERT OR REPLACE INTO nodes VALUES (?, ?, ?)", nodes)
    db.executemany(
        "INSERT OR REPLACE INTO ways VALUES (?, ?, ?)",
        [(w, _blob(refs), None if t is None else json.dumps(t)) for w, refs, t in ways],
    )
    db.executemany("INSERT OR IGNORE INTO node_ways VALUES (?, ?)",
                   [(n, w) for w, refs, t in ways if t is not None for n in refs])  # fmt: skip
    for r, members, tags in rels:
        _put_relation(db, r, members, tags)
    db.execute("CREATE INDEX IF NOT EXISTS node_ways_node ON node_ways (node)")
    db.execute("CREATE INDEX IF NOT EXISTS node_ways_way ON node_ways (way)")
    db.execute("CREATE INDEX IF NOT EXISTS way_rels_way ON way_rels (way)")
    db.execute("CREATE INDEX IF NOT EXISTS way_rels_rel ON way_rels (rel)")


def _put_relation(db, r, members, tags):
    db.execute("INSERT OR REPLACE INTO rels VALUES (?, ?, ?)", (r, json.dumps(members),
                                                                 json.dumps(tags)))  # fmt: skip
    for kind, ref, _ in members:
        if kind == "w":
            db.execute("INSERT OR IGNORE INTO way_rels VALUES (?, ?)", (ref, r))
            row = db.execute("SELECT nodes FROM ways WHERE id = ?", (ref,)).fetchone()
            if row is not None:
                db.executemany("INSERT OR IGNORE INTO node_ways VALUES (?, ?)",
                               [(n, ref) for n in _refs(row[0])])  # fmt: skip


@dataclass
class Changes:
    """The last version of every object the change files name.

    Attributes
    ----------
    nodes : dict
        id -> ``None`` (deleted) or ``(x, y, tags)`` (x, y: the location as 10^-7 degrees).
    ways : dict
        id -> ``None`` or ``(node ids, tags)``.
    relations : dict
        id -> ``None`` or ``(members, tags)``, members as ``(type, ref, role)``.
    files : list of str
    """

    nodes: dict = field(default_factory=dict)
    ways: dict = field(default_factory=dict)
    relations: dict = field(default_factory=dict)
    files: list = field(default_factory=list)

    def __len__(self):
        return len(self.nodes) + len(self.ways) + len(self.relations)


def read_changes(paths, stop=None) -> Changes:
    """Read OpenStreetMap change files (``.osc``, ``.osc.gz``, ``.osc.bz2``), applied in the
    order given: the last version of an object wins.

    Raises
    ------
    InputError
        One line naming the file: missing, or not a change file.
    """
    import osmium

    out = Changes()
    for path in paths:
        text = str(path)
        if ".osc" not in text.lower():
            raise InputError(path, "not an OpenStreetMap change file (.osc, .osc.gz)")
        try:
            for obj in osmium.FileProcessor(text):
                if obj.is_node():
                    loc = obj.location
                    tags = dict(obj.tags) if len(obj.tags) else {}  # most nodes have none
                    out.nodes[obj.id] = (
                        None if obj.deleted or not loc.valid() else (loc.x, loc.y, tags)
                    )
                elif obj.is_way():
                    out.ways[obj.id] = (
                        None if obj.deleted else ([n.ref for n in obj.nodes], dict(obj.tags))
                    )
                elif obj.is_relation():
                    members = [(m.type, m.ref, m.role) for m in obj.members]
                    out.relations[obj.id] = None if obj.deleted else (members, dict(obj.tags))
                if stop:
                    stop()
        except (RuntimeError, ValueError, OSError) as exc:
            if not __import__("os").path.isfile(text):
                raise InputError(path, "no such file") from None
            raise InputError(path, f"not a readable change file ({exc})") from None
        out.files.append(text)
    return out


def _in(db, sql, ids):
    ids = sorted(ids)
    out = set()
    for k in range(0, len(ids), 500):
        chunk = ids[k : k + 500]
        out.update(r[0] for r in db.execute(sql.format(",".join("?" * len(chunk))), chunk))
    return out


def apply_changes(db, changes: Changes, keys) -> dict:
    """Apply ``changes`` to the store's middle; the objects whose features may have changed.

    Returns
    -------
    dict
        ``{"node": ids, "way": ids, "relation": ids}``: the changed objects, the keyed ways
        and every way of a keyed relation on a changed node, and the keyed relations of those
        ways.
    """
    nodes = set(changes.nodes)
    ways = set(changes.ways) | _in(db, "SELECT way FROM node_ways WHERE node IN ({})", nodes)
    rels = set(changes.relations) | _in(db, "SELECT rel FROM way_rels WHERE way IN ({})", ways)
    items = changes.nodes.items()
    db.executemany("DELETE FROM nodes WHERE id = ?", [(n,) for n, v in items if v is None])
    db.executemany("INSERT OR REPLACE INTO nodes VALUES (?, ?, ?)",
                   [(n, v[0], v[1]) for n, v in items if v is not None])  # fmt: skip
    for w, value in changes.ways.items():
        db.execute("DELETE FROM ways WHERE id = ?", (w,))
        db.execute("DELETE FROM node_ways WHERE way = ?", (w,))
        if value is None:
            continue
        refs, tags = value
        tagged = keyed(tags, keys)
        db.execute("INSERT INTO ways VALUES (?, ?, ?)",
                   (w, _blob(refs), json.dumps(tags) if tagged else None))  # fmt: skip
        member = db.execute("SELECT 1 FROM way_rels WHERE way = ?", (w,)).fetchone()
        if tagged or member:
            db.executemany("INSERT OR IGNORE INTO node_ways VALUES (?, ?)", [(n, w) for n in refs])
    for r, value in changes.relations.items():
        db.execute("DELETE FROM rels WHERE id = ?", (r,))
        db.execute("DELETE FROM way_rels WHERE rel = ?", (r,))
        if value is not None and keyed(value[1], keys):
            _put_relation(db, r, *value)
    return {"node": nodes, "way": ways, "relation": rels}


def write_extract(db, touched, changes: Changes, path):
    """Write the touched objects that exist after the change, with the ways and nodes they are
    made of, as an OpenStreetMap file ``path`` (its suffix gives the format)."""
    import osmium
    from osmium.osm import mutable

    rels = {}
    for r in sorted(touched["relation"]):
        row = db.execute("SELECT members, tags FROM rels WHERE id = ?", (r,)).fetchone()
        if row is not None:
            rels[r] = ([tuple(m) for m in json.loads(row[0])], json.loads(row[1]))
    ways = {}
    for w in sorted(touched["way"]):
        row = db.execute("SELECT nodes, tags FROM ways WHERE id = ?", (w,)).fetchone()
        if row is not None and row[1] is not None:
            ways[w] = (_refs(row[0]), json.loads(row[1]))
    for members, _ in rels.values():
        for kind, ref, _ in members:
            if kind == "w" and ref not in ways:
                row = db.execute("SELECT nodes FROM ways WHERE id = ?", (ref,)).fetchone()
                if row is not None:
                    ways[ref] = (_refs(row[0]), {})
    node_tags = {}
    for n in touched["node"]:
        value = changes.nodes.get(n)
        if value is not None and value[2]:
            node_tags[n] = value[2]
    wanted = set(node_tags)
    for refs, _ in ways.values():
        wanted.update(refs)
    places = {}
    ids = sorted(wanted)
    for k in range(0, len(ids), 500):
        chunk = ids[k : k + 500]
        marks = ",".join("?" * len(chunk))
        for n, x, y in db.execute(f"SELECT id, x, y FROM nodes WHERE id IN ({marks})", chunk):
            places[n] = (x / 1e7, y / 1e7)
    with osmium.SimpleWriter(str(path)) as writer:
        for n in sorted(places):
            writer.add_node(mutable.Node(id=n, location=places[n], tags=node_tags.get(n, {})))
        for w in sorted(ways):
            refs, tags = ways[w]
            writer.add_way(mutable.Way(id=w, nodes=refs, tags=tags))
        for r in sorted(rels):
            members, tags = rels[r]
            writer.add_relation(mutable.Relation(id=r, members=members, tags=tags))
