"""Restricted features kept on disk while a large build is read, with the little each needs
in memory to be planned: its extent, width and class.

A country's restricted features do not fit in memory as Python objects (some 34 kB each
once grouped and fenced). The spool holds each as a compact record (WKB geometry, tags,
source, rule) in an anonymous temporary file that disappears with the process; tile jobs
take their records from it and turn them back into features where they run.

A record is an 8-byte header (the indices of its origin and rule in the spool's tables) and
a pickle of the rest, so records encoded in another process (:meth:`Spool.encode`) take this
spool's indices by a rewrite of their headers (:meth:`Spool.add_encoded`).
"""

from __future__ import annotations

import os
import pickle
import struct
import tempfile

import numpy as np
import shapely

from alphafence.fencing.regions import outward
from alphafence.zones.features import Feature

HEADER = struct.Struct("<II")  # origin, rule


class Spool:
    """Features written to a temporary file, read back by index.

    Parameters
    ----------
    directory : str, optional
        Where the temporary file lives (default: the system's temporary directory).

    Attributes
    ----------
    bounds : ndarray of float32, shape (n, 4)
        Each feature's extent (lon, lat), rounded outwards: it holds the feature.
    widths : ndarray of float32, shape (n,)
        Metres each is widened by before grouping, rounded up.
    classes : ndarray of int, shape (n,)
        An index into :attr:`class_keys` per feature.
    class_keys : list
        The distinct ``site_class`` keys, in order of first appearance.
    rules : list of Rule
        The rules the features matched, referred to by index in records.

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.zones.database import read_database
    >>> from alphafence.zones.rules import load_rules
    >>> rules = load_rules()
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> features = read_database(str(scene), rules).features
    >>> with Spool() as spool:
    ...     spool.add(features, [0.0] * len(features), [0] * len(features))
    ...     back = Spool.decode(spool.records([3, 0]), spool.rules, spool.origins)
    >>> [f.source for f in back] == [features[3].source, features[0].source]
    True
    >>> back[0].geometry.equals_exact(features[3].geometry, 0)
    True
    """

    def __init__(self, directory=None):
        self._fh = tempfile.TemporaryFile(dir=directory)  # noqa: SIM115 (closed by close())
        self._end = 0
        self._offsets, self._bounds, self._widths, self._classes = [], [], [], []
        self.rules, self._rule_index = [], {}
        self.origins, self._origin_index = [], {}
        self.class_keys, self._class_index = [], {}
        self._frozen = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Drop the temporary file."""
        self._fh.close()

    def __len__(self):
        return sum(len(o) for o in self._offsets)

    def class_of(self, key) -> int:
        """The index of a ``site_class`` key (added when new)."""
        i = self._class_index.get(key)
        if i is None:
            i = self._class_index[key] = len(self.class_keys)
            self.class_keys.append(key)
        return i

    def _index(self, table, index, value):
        i = index.get(value)
        if i is None:
            i = index[value] = len(table)
            table.append(value)
        return i

    def add(self, features, widths, classes):
        """Append features (with their widths and class indices) to the spool."""
        if not len(features):
            return
        origins = [self._index(self.origins, self._origin_index, f.origin) for f in features]
        rules = [self._index(self.rules, self._rule_index, f.rule) for f in features]
        geoms = np.array([f.geometry for f in features], dtype=object)
        data, lengths = self.encode(features, origins, rules)
        self._append(data, lengths, shapely.bounds(geoms), widths, classes)

    @staticmethod
    def encode(features, origins, rules):
        """Features as spool records (in any process).

        Parameters
        ----------
        features : list of Feature
        origins, rules : sequence of int
            Each feature's origin and rule, as indices into tables (rewritten by
            :meth:`add_encoded` when they are not this spool's).

        Returns
        -------
        data : bytes
            The records, one after the other.
        lengths : ndarray of int64
            Each record's length.
        """
        wkb = shapely.to_wkb(np.array([f.geometry for f in features], dtype=object))
        chunks = []
        for f, g, o, k in zip(features, wkb, origins, rules):
            chunks.append(HEADER.pack(o, k))
            chunks.append(
                pickle.dumps(
                    (g, f.tags, f.source, f.alt_min_m, f.alt_max_m, f.properties or None),
                    protocol=pickle.HIGHEST_PROTOCOL,
                )
            )
        lengths = np.fromiter(map(len, chunks), np.int64, len(chunks))
        return b"".join(chunks), lengths[0::2] + lengths[1::2]

    def add_encoded(self, data, lengths, bounds, widths, classes, origins, rules):
        """Append records :meth:`encode` made elsewhere, with tables of their own.

        Parameters
        ----------
        data : bytes
        lengths : ndarray of int
            As :meth:`encode` returns them.
        bounds : ndarray, shape (n, 4)
        widths : ndarray, shape (n,)
        classes, origins, rules : tuple
            ``(keys, ids)``: the distinct ``site_class`` keys, origins and Rule objects the
            records refer to, and each record's index into them; they become this spool's.
        """
        if not len(lengths):
            return
        table = {
            "classes": [self.class_of(key) for key in classes[0]],
            "origins": [self._index(self.origins, self._origin_index, o) for o in origins[0]],
            "rules": [self._index(self.rules, self._rule_index, r) for r in rules[0]],
        }
        header = np.empty((len(lengths), 2), dtype="<u4")
        header[:, 0] = np.asarray(table["origins"], dtype=np.int64)[origins[1]]
        header[:, 1] = np.asarray(table["rules"], dtype=np.int64)[rules[1]]
        data = bytearray(data)
        starts = np.cumsum(lengths) - lengths
        np.frombuffer(data, np.uint8)[starts[:, None] + np.arange(HEADER.size)] = header.view(
            np.uint8
        ).reshape(-1, HEADER.size)
        ids = np.asarray(table["classes"], dtype=np.int32)[classes[1]]
        self._append(data, lengths, bounds, widths, ids)

    def _append(self, data, lengths, bounds, widths, classes):
        self._fh.seek(self._end)
        self._fh.write(data)
        self._offsets.append(self._end + np.cumsum(lengths) - lengths)
        self._end += len(data)
        bounds = np.asarray(bounds, dtype=float).reshape(-1, 4)
        self._bounds.append(np.column_stack([outward(bounds[:, :2], up=False),
                                             outward(bounds[:, 2:], up=True)]))  # fmt: skip
        self._widths.append(outward(widths, up=True))
        self._classes.append(np.asarray(classes, dtype=np.int32))
        self._frozen = None

    def _arrays(self):
        if self._frozen is None:
            self._fh.flush()
            # one column at a time, its batches let go as it is joined: memory holds the
            # columns and one column's batches, never all of them twice
            self._offsets.append(np.array([self._end], dtype=np.int64))
            columns = []
            for parts, empty in (
                (self._offsets, None),
                (self._bounds, np.empty((0, 4), np.float32)),
                (self._widths, np.empty(0, np.float32)),
                (self._classes, np.empty(0, np.int32)),
            ):
                joined = np.concatenate(parts) if parts or empty is None else empty
                parts.clear()
                parts.append(joined)
                columns.append(joined)
            self._offsets[0] = columns[0][:-1]
            self._frozen = tuple(columns)
        return self._frozen

    @property
    def bounds(self):
        return self._arrays()[1]

    @property
    def widths(self):
        return self._arrays()[2]

    @property
    def classes(self):
        return self._arrays()[3]

    def records(self, indices) -> list:
        """The raw records of the given features, in the order given."""
        offsets = self._arrays()[0]
        fd = self._fh.fileno()
        out = []
        for i in np.asarray(indices, dtype=np.int64):
            start, end = int(offsets[i]), int(offsets[i + 1])
            out.append(os.pread(fd, end - start, start))
        return out

    @staticmethod
    def decode(records, rules, origins) -> list:
        """Features back from raw records (in a worker process or here).

        Parameters
        ----------
        records : list of bytes
        rules : list of Rule
            :attr:`rules` of the spool that wrote them.
        origins : list of str
            :attr:`origins` of that spool.

        Returns
        -------
        list of Feature
        """
        heads = [HEADER.unpack_from(r) for r in records]
        rows = [pickle.loads(memoryview(r)[HEADER.size :]) for r in records]
        geoms = shapely.from_wkb([r[0] for r in rows])
        return [
            Feature(g, tags, source, origins[o], rules[k], lo, hi, props or {})
            for g, (o, k), (_, tags, source, lo, hi, props) in zip(geoms, heads, rows)
        ]
