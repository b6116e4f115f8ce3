"""Restricted features kept on disk while a large build is read, with the little each needs
in memory to be planned: its extent, width and class.

A country's restricted features do not fit in memory as Python objects (some 34 kB each
once grouped and fenced). The spool holds each as a compact record (WKB geometry, tags,
source, rule) in an anonymous temporary file that disappears with the process; tile jobs
take their records from it and turn them back into features where they run.
"""

from __future__ import annotations

import os
import pickle
import tempfile

import numpy as np
import shapely

from alphafence.formats.features import Feature


class Spool:
    """Features written to a temporary file, read back by index.

    Parameters
    ----------
    directory : str, optional
        Where the temporary file lives (default: the system's temporary directory).

    Attributes
    ----------
    bounds : ndarray, shape (n, 4)
        Each feature's extent (lon, lat).
    widths : ndarray, shape (n,)
        Metres each is widened by before grouping.
    classes : ndarray of int, shape (n,)
        An index into :attr:`class_keys` per feature.
    class_keys : list
        The distinct ``site_class`` keys, in order of first appearance.
    rules : list of Rule
        The rules the features matched, referred to by index in records.

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.formats.database import read_database
    >>> from alphafence.formats.rules import load_rules
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
        geoms = np.array([f.geometry for f in features], dtype=object)
        wkb = shapely.to_wkb(geoms)
        chunks, offsets = [], np.empty(len(features), dtype=np.int64)
        pos = self._end
        for i, (f, g) in enumerate(zip(features, wkb)):
            rec = pickle.dumps(
                (
                    g,
                    f.tags,
                    f.source,
                    self._index(self.origins, self._origin_index, f.origin),
                    self._index(self.rules, self._rule_index, f.rule),
                    f.alt_min_m,
                    f.alt_max_m,
                    f.properties or None,
                ),
                protocol=pickle.HIGHEST_PROTOCOL,
            )
            offsets[i] = pos
            pos += len(rec)
            chunks.append(rec)
        self._fh.seek(self._end)
        self._fh.write(b"".join(chunks))
        self._end = pos
        self._offsets.append(offsets)
        self._bounds.append(shapely.bounds(geoms))
        self._widths.append(np.asarray(widths, dtype=float))
        self._classes.append(np.asarray(classes, dtype=np.int32))
        self._frozen = None

    def _arrays(self):
        if self._frozen is None:
            self._fh.flush()
            n = len(self)
            offsets = np.concatenate(self._offsets + [np.array([self._end], dtype=np.int64)])
            self._frozen = (
                offsets,
                np.concatenate(self._bounds) if n else np.empty((0, 4)),
                np.concatenate(self._widths) if n else np.empty(0),
                np.concatenate(self._classes) if n else np.empty(0, np.int32),
            )
            self._offsets, self._bounds = [offsets[:-1]], [self._frozen[1]]
            self._widths, self._classes = [self._frozen[2]], [self._frozen[3]]
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
        rows = [pickle.loads(r) for r in records]
        geoms = shapely.from_wkb([r[0] for r in rows])
        return [
            Feature(g, tags, source, origins[o], rules[k], lo, hi, props or {})
            for g, (_, tags, source, o, k, lo, hi, props) in zip(geoms, rows)
        ]
