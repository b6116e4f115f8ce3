"""What a build keeps for its updates: the restricted features it fenced, with the extent each
region is found by, in an SQLite file beside the fences (``alphafence build --store``).

A feature's row holds its record (WKB geometry, tags, source, origin, rule, altitude band),
its ``site_class`` key and its extent grown as :func:`alphafence.fencing.regions.grown_bounds`
grows it; an R*Tree over the grown extents finds a region's members without reading the rest.
An OpenStreetMap build adds the extract's nodes and ways (:mod:`alphafence.updating.middle`)
so a change that names a node finds the areas it moves.

Every change runs in one SQLite transaction, committed only once the fences are written.
"""

from __future__ import annotations

import json
import pickle
import sqlite3
from pathlib import Path

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.fencing.regions import grown_bounds
from alphafence.fencing.sites import feature_widths, site_class
from alphafence.zones.features import Feature

FORMAT = 1  # the store's layout; a store of another layout is refused with one line
LOCK_WAIT_S = 600.0  # how long an update waits for another that holds the store

SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE features (id INTEGER PRIMARY KEY, source TEXT NOT NULL, cls TEXT NOT NULL,
    gx0 REAL NOT NULL, gy0 REAL NOT NULL, gx1 REAL NOT NULL, gy1 REAL NOT NULL,
    record BLOB NOT NULL);
CREATE INDEX features_source ON features (source);
CREATE VIRTUAL TABLE feature_box USING rtree (id, x0, x1, y0, y1);
"""


class Store:
    """An update store, open (and locked) for one build or update.

    Parameters
    ----------
    path : str or Path
    create : bool
        Make a new store at ``path`` (which must not exist: the build writes it beside and
        moves it over).

    Raises
    ------
    InputError
        No such store, not one, or of another layout.
    """

    def __init__(self, path, create=False):
        self.path = Path(path)
        if not create and not self.path.is_file():
            raise InputError(self.path, "no such update store (build with --store to make one)")
        try:
            # a second update waits for the first (cron's next run over a long one)
            self.db = sqlite3.connect(self.path, isolation_level=None, timeout=LOCK_WAIT_S)
            self.db.execute("PRAGMA journal_mode=WAL" if not create else "PRAGMA journal_mode=OFF")
            if create:
                self.db.execute("PRAGMA synchronous=OFF")
                self.db.executescript(SCHEMA)
                self.set_meta("format", FORMAT)
            elif self.meta("format") != FORMAT:
                raise InputError(self.path, f"an update store of another layout ({FORMAT} read)")
            self.db.execute("BEGIN IMMEDIATE")  # the whole run is one transaction
        except sqlite3.OperationalError as exc:
            if "locked" in str(exc):
                raise InputError(self.path, f"another update has held the store for over "
                                 f"{LOCK_WAIT_S:.0f} s") from None  # fmt: skip
            raise InputError(self.path, f"not an update store ({exc})") from None
        except sqlite3.DatabaseError as exc:
            raise InputError(self.path, f"not an update store ({exc})") from None
        self._rules = None

    # -- the transaction -------------------------------------------------------------------
    def commit(self):
        """Make this run's changes the store's."""
        self.db.execute("COMMIT")

    def close(self):
        """Close; changes not committed are dropped."""
        if self.db.in_transaction:
            self.db.execute("ROLLBACK")
        self.db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- what the build was ----------------------------------------------------------------
    def set_meta(self, key, value):
        """Keep ``value`` (anything JSON can hold) under ``key``."""
        self.db.execute(
            "INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value))
        )

    def meta(self, key, default=None):
        """The value kept under ``key``."""
        row = self.db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return default if row is None else json.loads(row[0])

    def rules(self):
        """The build's rules, parsed from the text it kept (a rules file edited since does not
        change what an update makes)."""
        if self._rules is None:
            import tomllib

            from alphafence.zones.rules import parse_rules

            self._rules = parse_rules(tomllib.loads(self.meta("rules_text")), self.meta("rules"))
        return self._rules

    # -- features --------------------------------------------------------------------------
    def add(self, features, join_m):
        """Add restricted features; their ids, in order."""
        if not features:
            return []
        rules = self.rules()
        index = {rule: i for i, rule in enumerate(rules.rules)}
        geoms = np.array([f.geometry for f in features], dtype=object)
        grown = grown_bounds(shapely.bounds(geoms), feature_widths(features, rules), join_m)
        wkb = shapely.to_wkb(geoms)
        rows = []
        for f, g, b in zip(features, wkb, grown.tolist()):
            record = (g, f.tags, f.source, f.origin, index[f.rule], f.alt_min_m, f.alt_max_m,
                      f.properties or None)  # fmt: skip
            rows.append((f.source, repr(site_class(f)), *b,
                         pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL)))  # fmt: skip
        start = self._next_id()
        ids = list(range(start, start + len(rows)))
        self.db.executemany(
            "INSERT INTO features (id, source, cls, gx0, gy0, gx1, gy1, record) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            [(i, *r) for i, r in zip(ids, rows)],
        )
        self.db.executemany(
            "INSERT INTO feature_box (id, x0, x1, y0, y1) VALUES (?, ?, ?, ?, ?)",
            [(i, r[2], r[4], r[3], r[5]) for i, r in zip(ids, rows)],
        )
        return ids

    def _next_id(self):
        row = self.db.execute("SELECT coalesce(max(id), 0) FROM features").fetchone()
        return int(row[0]) + 1

    def remove(self, ids):
        """Drop features by id."""
        rows = [(i,) for i in ids]
        self.db.executemany("DELETE FROM features WHERE id = ?", rows)
        self.db.executemany("DELETE FROM feature_box WHERE id = ?", rows)

    def ids_of(self, sources):
        """The ids of the features read from these sources."""
        out = []
        for chunk in _chunks(sorted(set(sources))):
            marks = ",".join("?" * len(chunk))
            out += [r[0] for r in self.db.execute(
                f"SELECT id FROM features WHERE source IN ({marks})", chunk)]  # fmt: skip
        return sorted(out)

    def features(self, ids):
        """The features by id, in the order of ``ids``."""
        rules = self.rules().rules
        by_id = {}
        for chunk in _chunks(list(ids)):
            marks = ",".join("?" * len(chunk))
            for i, blob in self.db.execute(
                f"SELECT id, record FROM features WHERE id IN ({marks})", chunk
            ):
                by_id[i] = blob
        out = []
        records = [pickle.loads(by_id[i]) for i in ids]
        geoms = shapely.from_wkb([r[0] for r in records])
        for g, (_, tags, source, origin, rule, lo, hi, props) in zip(geoms, records):
            out.append(Feature(g, tags, source, origin, rules[rule], lo, hi, props or {}))
        return out

    def count(self):
        """Features kept."""
        return self.db.execute("SELECT count(*) FROM features").fetchone()[0]

    def region_of(self, seeds):
        """Every feature in the regions of the features ``seeds`` (ids): those of the same
        class whose grown extents meet theirs, directly or through others, as
        :func:`alphafence.fencing.regions.region_labels` joins them."""
        seen = set(seeds)
        frontier = sorted(seen)
        while frontier:
            boxes = []
            for chunk in _chunks(frontier):
                marks = ",".join("?" * len(chunk))
                boxes += self.db.execute(
                    f"SELECT cls, gx0, gy0, gx1, gy1 FROM features WHERE id IN ({marks})", chunk
                ).fetchall()
            frontier = []
            for cls, x0, y0, x1, y1 in boxes:
                # the R*Tree's 32-bit bounds are rounded outwards: a superset, then the test
                for (i,) in self.db.execute(
                    "SELECT f.id FROM feature_box b JOIN features f ON f.id = b.id "
                    "WHERE b.x1 >= ? AND b.x0 <= ? AND b.y1 >= ? AND b.y0 <= ? "
                    "AND f.cls = ? AND f.gx1 >= ? AND f.gx0 <= ? AND f.gy1 >= ? AND f.gy0 <= ?",
                    (x0, x1, y0, y1, cls, x0, x1, y0, y1),
                ):
                    if i not in seen:
                        seen.add(i)
                        frontier.append(i)
        return sorted(seen)


def _chunks(items, size=500):
    for k in range(0, len(items), size):
        yield items[k : k + size]
