"""A large GeoJSON text sequence read in the worker processes, chunk by chunk, while the main
process only cuts the file at record boundaries and spools what the workers return, in order
(and reads chunks itself until a worker has started: a pool takes a while to import).

A worker reads its chunk as the serial reader reads that batch (the same records, indices,
line numbers and errors: :func:`alphafence.zones.geojson_stream.read_chunk`), keeps the
features inside the bounding box, and returns them as spool records with their extents,
widths and ``site_class`` keys. Tables of origins, rules and classes stay in the main process:
a worker refers to its own and the spool maps them (:meth:`Spool.add_encoded`), so the spool,
and every output, is byte for byte the serial read's.
"""

from __future__ import annotations

import gc
from collections import Counter, deque
from dataclasses import dataclass, field

from alphafence.errors import InputError
from alphafence.fencing.sites import feature_widths, site_class
from alphafence.fencing.spool import Spool
from alphafence.zones.features import select_bbox, settle_faults
from alphafence.zones.geojson_stream import (
    BATCH,
    Unchunkable,
    iter_geojson,
    read_chunk,
    sequence_chunks,
)


@dataclass
class ReadChunk:
    """What a worker read from one chunk: the restricted features inside the bounding box as
    spool records, and what :class:`Spool.add_encoded` needs with them.

    Attributes
    ----------
    data : bytes
        The records (:meth:`Spool.encode`).
    lengths, bounds, widths : ndarray
        Per record: its length, its extent (lon, lat), its width in metres.
    classes, origins, rules : tuple
        ``(keys, ids)``: the distinct ``site_class`` keys, origins and rules (positions in
        the rules' list, to be mapped to the main process's Rule objects), in order of first
        appearance, and each record's index into them.
    repaired : list of str
        Sources of invalid polygons in the chunk, inside the box or not.
    skipped : collections.Counter
        Features the chunk left out, by reason.
    faults : list of tuple
        ``(path, message, feature)`` of each malformed feature (an InputError's parts: the
        exception itself does not survive pickling).
    """

    data: bytes = b""
    lengths: object = ()
    bounds: object = ()
    widths: object = ()
    classes: tuple = ((), ())
    origins: tuple = ((), ())
    rules: tuple = ((), ())
    repaired: list = field(default_factory=list)
    skipped: Counter = field(default_factory=Counter)
    faults: list = field(default_factory=list)

    def __len__(self):
        return len(self.lengths)

    def add_to(self, spool, rules):
        """Append the records to ``spool``, their rules mapped to ``rules``' own objects."""
        keys, ids = self.rules
        spool.add_encoded(
            self.data,
            self.lengths,
            self.bounds,
            self.widths,
            self.classes,
            self.origins,
            ([rules.rules[k] for k in keys], ids),
        )


def _table(values):
    """``(distinct values in order of first appearance, each value's index)``.

    Examples
    --------
    >>> _table(["b", "a", "b"])
    (['b', 'a'], array([0, 1, 0], dtype=int32))
    """
    import numpy as np

    index = {}
    ids = np.fromiter((index.setdefault(v, len(index)) for v in values), np.int32, len(values))
    return list(index), ids


def read_job(path, chunk, rules, bbox):
    """Read one chunk (in a worker process).

    Parameters
    ----------
    path : str
    chunk : SeqChunk
    rules : Rules
    bbox : tuple, optional

    Returns
    -------
    ReadChunk, or ``("error", path, message, feature)`` for the InputError the serial reader
    raises there (the exception itself does not survive pickling), or ``("unchunkable",)``
    when the rest of the file must be read serially.
    """
    enabled = gc.isenabled()
    gc.disable()  # parsed JSON makes no cycles: a chunk's objects would only be traversed
    try:
        return _read_job(path, chunk, rules, bbox)
    finally:
        if enabled:
            gc.enable()


def _read_job(path, chunk, rules, bbox):
    import numpy as np
    import shapely

    out, faults = ReadChunk(), []
    try:
        features = read_chunk(path, chunk, rules, out.repaired, out.skipped, faults)
    except InputError as exc:
        return ("error", exc.path, exc.message, exc.feature)
    except Unchunkable:
        return ("unchunkable",)
    out.faults = [(e.path, e.message, e.feature) for e in faults]
    features = select_bbox(features, bbox)
    if not features:
        return out
    position = {id(r): i for i, r in enumerate(rules.rules)}
    out.classes = _table([site_class(f) for f in features])
    out.origins = _table([f.origin for f in features])
    out.rules = _table([position[id(f.rule)] for f in features])
    out.data, out.lengths = Spool.encode(features, out.origins[1], out.rules[1])
    out.bounds = shapely.bounds(np.array([f.geometry for f in features], dtype=object))
    out.widths = feature_widths(features, rules)
    return out


def sequence_reader(pool, window, batch=BATCH):
    """A reader of GeoJSON text sequences in ``pool``'s workers, for
    :meth:`alphafence.zones.database.DatabaseStream.batches`.

    Parameters
    ----------
    pool : concurrent.futures.Executor
        Worker processes (:func:`alphafence.fencing.tile_jobs.start_pool`).
    window : int
        Chunks in flight at most (memory holds their features as records).
    batch : int
        Records per chunk: the serial reader's batch, so both raise the same first error.

    Returns
    -------
    callable
        ``read(path, rules, bbox, repaired, skipped, invalid)`` -> an iterator of
        :class:`ReadChunk` (and, for a file's end that must be read serially, lists of
        Feature), in file order, each inside ``bbox``; ``repaired`` and ``skipped`` extended
        chunk by chunk, in order; malformed features described in ``invalid``, or (None)
        raised at the file's end, as the serial reader raises them. None when the file cannot
        be opened (the serial reader says why).
    """

    def read(path, rules, bbox, repaired, skipped, invalid=None):
        try:
            open(path, "rb").close()
        except OSError:
            return None
        return _read(pool, window, batch, str(path), rules, bbox, repaired, skipped, invalid)

    return read


def _read(pool, window, batch, path, rules, bbox, repaired, skipped, invalid):
    chunks = sequence_chunks(path, batch)
    pending, rest, faults = deque(), [], []

    def fill():  # keep the workers busy while this process spools what they returned
        while not rest and len(pending) < window:
            chunk = next(chunks, None)
            if chunk is None:
                return
            if chunk.records is None:
                rest.append(chunk)
            elif not ready.done():  # read here while the workers start: one chunk at a time
                pending.append((chunk, None))
                return
            else:
                pending.append((chunk, pool.submit(read_job, path, chunk, rules, bbox)))

    ready = pool.submit(int)  # done once a worker has started (imported the fencing code)
    try:
        fill()
        while pending:
            chunk, future = pending.popleft()
            out = read_job(path, chunk, rules, bbox) if future is None else future.result()
            if isinstance(out, tuple) and out[0] == "error":
                raise InputError(*out[1:])
            if isinstance(out, tuple):  # unchunkable: this chunk on, as the serial reader
                rest[:] = [chunk]
                break
            repaired.extend(out.repaired)
            skipped.update(out.skipped)
            faults.extend(InputError(*fault) for fault in out.faults)
            fill()
            yield out
    finally:
        for _, future in pending:
            if future is not None:
                future.cancel()
        chunks.close()
    for chunk in rest:
        skip = (chunk.line - 1, chunk.index)
        for part in iter_geojson(path, rules, repaired, skipped, batch, skip, faults=faults):
            yield select_bbox(part, bbox)
    settle_faults(path, faults, invalid)
