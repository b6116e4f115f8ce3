"""A small OpenStreetMap world written by the tests (never a copy of OSM's data): buildings
some of which are hospitals, schools or prisons, multipolygon hospitals made of untagged
ways, helipads as tagged nodes; edits of every kind OpenStreetMap's changes carry, the
changed world, and the change file (``.osc``) between them, as pyosmium writes it."""

from __future__ import annotations

import copy
import math
import random

import osmium
from osmium.osm import mutable

LON0, LAT0 = 14.5, 35.9
M_LAT = 1 / 110_574.0
M_LON = 1 / (111_320.0 * math.cos(math.radians(LAT0)))
KINDS = [{"amenity": "hospital"}, {"amenity": "school"}, {"amenity": "prison"},
         {"building": "yes"}, {"building": "yes"}]  # fmt: skip


class World:
    """Nodes ``{id: (lon, lat, tags)}``, ways ``{id: (refs, tags)}``, relations
    ``{id: (members, tags)}``; ``changed`` names what edits touched since :meth:`mark`."""

    def __init__(self, seed=0, buildings=36):
        rng = random.Random(seed)
        self.nodes, self.ways, self.rels = {}, {}, {}
        self.next = {"n": 1, "w": 1, "r": 1}
        for k in range(buildings):
            x, y = (k % 6) * 70 + rng.uniform(-15, 15), (k // 6) * 70 + rng.uniform(-15, 15)
            self.building(x, y, rng.uniform(15, 45), rng.uniform(15, 45), dict(rng.choice(KINDS)))
        for k in range(2):  # multipolygon hospitals whose outer ways carry no tags
            w = self.building(480 + 60 * k, 100 + 60 * k, 40, 30, {})
            self.relation([("w", w, "outer")], {"type": "multipolygon", "amenity": "hospital"})
        for k in range(3):
            self.node(100 * k + 35, 450, {"aeroway": "helipad"})
        self.mark()

    # -- making --------------------------------------------------------------------------
    def _id(self, kind):
        i = self.next[kind]
        self.next[kind] += 1
        return i

    def node(self, x, y, tags=None):
        """A node at x, y metres from the world's origin."""
        n = self._id("n")
        self.nodes[n] = (LON0 + x * M_LON, LAT0 + y * M_LAT, dict(tags or {}))
        self.changed["n"].add(n) if hasattr(self, "changed") else None
        return n

    def building(self, x, y, w, h, tags):
        """A closed way around a w x h metre rectangle."""
        refs = [self.node(x, y), self.node(x + w, y), self.node(x + w, y + h), self.node(x, y + h)]
        way = self._id("w")
        self.ways[way] = ([*refs, refs[0]], dict(tags))
        self.changed["w"].add(way) if hasattr(self, "changed") else None
        return way

    def relation(self, members, tags):
        r = self._id("r")
        self.rels[r] = (list(members), dict(tags))
        self.changed["r"].add(r) if hasattr(self, "changed") else None
        return r

    def mark(self):
        """Start counting edits (the next change file holds what changes after this)."""
        self.changed = {"n": set(), "w": set(), "r": set()}

    # -- edits, each as an OpenStreetMap change carries it --------------------------------
    def edit(self, rng):
        """One random edit; its name."""
        kind = rng.choice(["move", "move", "delete_way", "add", "retag", "add_relation",
                           "members", "delete_relation", "point"])  # fmt: skip
        ways = sorted(self.ways)
        if kind == "move" and self.nodes:
            n = rng.choice(sorted(self.nodes))
            lon, lat, tags = self.nodes[n]
            dx, dy = rng.uniform(-40, 40), rng.uniform(-40, 40)
            self.nodes[n] = (lon + dx * M_LON, lat + dy * M_LAT, tags)
            self.changed["n"].add(n)
        elif kind == "delete_way" and ways:
            w = rng.choice(ways)
            del self.ways[w]
            self.changed["w"].add(w)
        elif kind == "add":
            x, y = rng.uniform(-50, 550), rng.uniform(-50, 500)
            self.building(x, y, rng.uniform(10, 50), rng.uniform(10, 50), dict(rng.choice(KINDS)))
        elif kind == "retag" and ways:
            w = rng.choice(ways)
            self.ways[w] = (self.ways[w][0], dict(rng.choice(KINDS)))
            self.changed["w"].add(w)
        elif kind == "add_relation" and ways:
            outer = rng.choice(ways)
            tags = {"type": "multipolygon", **rng.choice(KINDS[:3])}
            self.relation([("w", outer, "outer")], tags)
        elif kind == "members" and self.rels and ways:
            r = rng.choice(sorted(self.rels))
            self.rels[r] = ([("w", rng.choice(ways), "outer")], self.rels[r][1])
            self.changed["r"].add(r)
        elif kind == "delete_relation" and self.rels:
            r = rng.choice(sorted(self.rels))
            del self.rels[r]
            self.changed["r"].add(r)
        elif kind == "point":
            points = sorted(n for n, v in self.nodes.items() if v[2])
            if points and rng.random() < 0.5:
                n = rng.choice(points)
                del self.nodes[n]  # a helipad removed (no way uses it)
                self.changed["n"].add(n)
            else:
                self.node(rng.uniform(0, 500), rng.uniform(0, 500), {"aeroway": "helipad"})
        return kind

    # -- files ----------------------------------------------------------------------------
    def write(self, path):
        """The world as an OpenStreetMap file (sorted, as an extract is)."""
        with osmium.SimpleWriter(str(path)) as w:
            for n in sorted(self.nodes):
                lon, lat, tags = self.nodes[n]
                w.add_node(mutable.Node(id=n, location=(lon, lat), tags=tags, version=1))
            for i in sorted(self.ways):
                refs, tags = self.ways[i]
                w.add_way(mutable.Way(id=i, nodes=refs, tags=tags, version=1))
            for r in sorted(self.rels):
                members, tags = self.rels[r]
                w.add_relation(mutable.Relation(id=r, members=members, tags=tags, version=1))

    def write_changes(self, path):
        """What changed since :meth:`mark` as a change file (deletions not visible)."""
        kinds = (("n", self.nodes, mutable.Node, "add_node", lambda v: {"location": v[:2]}),
                 ("w", self.ways, mutable.Way, "add_way", lambda v: {"nodes": v[0]}),
                 ("r", self.rels, mutable.Relation, "add_relation",
                  lambda v: {"members": v[0]}))  # fmt: skip
        with osmium.SimpleWriter(str(path)) as w:
            for key, table, make, add, shape in kinds:
                for i in sorted(self.changed[key]):
                    if i in table:  # its last version, else deleted (not visible)
                        obj = make(id=i, tags=table[i][-1], version=2, **shape(table[i]))
                    else:
                        obj = make(id=i, version=2, visible=False)
                    getattr(w, add)(obj)

    def copy(self):
        return copy.deepcopy(self)
