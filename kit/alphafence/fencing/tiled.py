"""The build at country scale: stream the database, spool its restricted features, plan tile
jobs, fence them on every core when the database is large enough to pay for the workers (or on
a Dask cluster) and hand each job's fences to the writers as it completes, in a fixed order.

Memory holds the features' extents (some 60 bytes each), a few tile jobs in flight and the
writers' buffers; never the country's fences. The fences are exactly the untiled build's
(:func:`alphafence.fencing.pipeline.build_fences`): the same sites, the same geometry.
"""

from __future__ import annotations

import os
import time
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass, field

import numpy as np

from alphafence.fencing.read_jobs import sequence_reader
from alphafence.fencing.sites import feature_widths, site_class
from alphafence.fencing.spool import Spool
from alphafence.fencing.tile_jobs import (
    JobInput,
    run_dask,
    run_local,
    run_processes,
    start_pool,
    stop_on_exit,
)
from alphafence.fencing.tiles import TARGET_FEATURES, TILE_DEG, plan_jobs
from alphafence.mavlink.items import MAX_POLYGON_VERTICES
from alphafence.zones.geojson_stream import BATCH

WARM_POOL_BYTES = 32 * 2**20  # databases larger than this start the workers before reading
AUTO_FEATURES = 5_000  # fewer restricted features than this are fenced in one process by default
READ_BATCH = BATCH  # records per chunk of a text sequence read in the workers


def default_jobs() -> int:
    """All the cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def auto_jobs(features: int, nbytes: int, cores: int | None = None) -> int:
    """The worker processes a build uses when not told (``--jobs auto``): every core for a
    database over :data:`WARM_POOL_BYTES` (32 MiB) or with at least :data:`AUTO_FEATURES`
    (5,000) restricted features, else one (this process). Starting a pool costs each worker
    the imports of the fencing code (half a second on a busy core), more than fencing a
    few thousand features takes; the fences are the same either way.

    Parameters
    ----------
    features : int
        Restricted features read.
    nbytes : int
        Size of the database's files.
    cores : int, optional
        Cores to use (default :func:`default_jobs`).

    Returns
    -------
    int

    Examples
    --------
    >>> auto_jobs(432, 3_861_052, cores=2), auto_jobs(13_300, 9_000_000, cores=2)
    (1, 2)
    >>> auto_jobs(10, 40 * 2**20, cores=4)
    4
    """
    cores = default_jobs() if cores is None else cores
    return cores if features >= AUTO_FEATURES or nbytes > WARM_POOL_BYTES else 1


def job_size(features: int) -> int:
    """Features per tile job: at least eight jobs (four for each of two workers, so none
    waits long on the last), at least 200 features (a job's fixed costs) and at most 2,000
    (memory in flight). It does not depend on the number of workers, so neither do the
    jobs, nor the order of the output's bytes.

    Examples
    --------
    >>> job_size(432), job_size(13_300), job_size(133_000), job_size(50)
    (200, 1663, 2000, 200)
    """
    return int(min(TARGET_FEATURES, max(200, -(-features // 8))))


LOOSE = 4.0  # a fence this many times its restricted area plus margin is named in the summary


@dataclass
class FenceStats:
    """What the build's summary says about its fences, gathered job by job in constant
    memory per category and kind (a million fences' rows would not be).

    Attributes
    ----------
    fences : int
    by_kind : dict
        ``(category, kind)`` -> ``[fences, area_m2, Counter(vertices -> fences)]``.
    repaired : list of str
        Site ids of fences re-united with their site (first 20).
    repaired_count : int
    oversized : list of str
        Site ids of polygons over ArduPilot's 255 vertices (first 20).
    oversized_count : int
    items : int
        Fence items the keep-out and keep-in fences make.
    loose : list of tuple
        ``(growth, site_id)`` of the main fences covering more than :data:`LOOSE` times
        their restricted area plus margin, the largest first (first 20).
    loose_count : int
    """

    fences: int = 0
    by_kind: dict = field(default_factory=dict)
    repaired: list = field(default_factory=list)
    repaired_count: int = 0
    oversized: list = field(default_factory=list)
    oversized_count: int = 0
    items: int = 0
    loose: list = field(default_factory=list)
    loose_count: int = 0

    def add(self, rows, max_vertices=MAX_POLYGON_VERTICES):
        """Count a job's rows (:func:`alphafence.fencing.tile_jobs.fence_rows`)."""
        for category, kind, vertices, area, repaired, site_id, circle, items, growth in rows:
            if kind != "warning" and growth > LOOSE:
                self.loose_count += 1
                self.loose = sorted([*self.loose, (growth, site_id)], reverse=True)[:20]
            entry = self.by_kind.setdefault((category, kind), [0, 0.0, Counter()])
            entry[0] += 1
            entry[1] += area
            entry[2][vertices] += 1
            self.fences += 1
            self.items += items
            if repaired:
                self.repaired_count += 1
                if len(self.repaired) < 20:
                    self.repaired.append(site_id)
            if kind != "warning" and not circle and vertices > max_vertices:
                self.oversized_count += 1
                if len(self.oversized) < 20:
                    self.oversized.append(site_id)


def median_of(counts) -> float:
    """The median of values given as a Counter (value -> how many).

    Examples
    --------
    >>> median_of(Counter({4: 1, 10: 2})), median_of(Counter({4: 1, 10: 1}))
    (10.0, 7.0)
    """
    values = sorted(counts)
    n = sum(counts.values())
    cum = np.cumsum([counts[v] for v in values])
    lo = values[int(np.searchsorted(cum, (n - 1) // 2 + 1))]
    hi = values[int(np.searchsorted(cum, n // 2 + 1))]
    return (lo + hi) / 2.0


@dataclass
class TiledResult:
    """What :func:`build_tiled` made.

    Attributes
    ----------
    features : int
        Restricted features read.
    sites : int
    site_kinds : collections.Counter
        ``(category, kind)`` -> sites.
    stats : FenceStats
        What the summary says about the fences.
    jobs : int
        Tile jobs run.
    fences, site_objects : list, optional
        Every Fence and Site, when asked to keep them.
    seconds : dict
        ``"read"`` (and spool, plan) and ``"fence"``.
    """

    features: int = 0
    sites: int = 0
    site_kinds: Counter = field(default_factory=Counter)
    stats: FenceStats = field(default_factory=FenceStats)
    jobs: int = 0
    fences: list | None = None
    site_objects: list | None = None
    seconds: dict = field(default_factory=dict)


def build_tiled(
    stream,
    rules,
    options,
    *,
    writers=(),
    jobs=None,
    dask=None,
    keep=False,
    progress=None,
    tile_deg=TILE_DEG,
    target=None,
    spool_dir=None,
    on_features=None,
) -> TiledResult:
    """Build the fences of a database of any size.

    Parameters
    ----------
    stream : DatabaseStream
        The database, read batch by batch.
    rules : Rules
    options : BuildOptions
    writers : sequence
        Output writers: ``encode`` runs where the job runs, ``write`` here, job by job.
    jobs : int, optional
        Worker processes (default :func:`auto_jobs`, chosen by the database's size; 1 = this
        process).
    dask : str, optional
        A Dask scheduler's address: run the jobs there instead.
    keep : bool
        Keep every Fence and Site in the result (for a figure or a vehicle's files).
    progress : callable, optional
        ``progress(phase, done, total)``: ``"reading"`` (features, total None) and
        ``"fencing"`` (features fenced of all).
    tile_deg : float
        Tile edge, degrees.
    target : int, optional
        Features per job to aim for (default :func:`job_size`).
    spool_dir : str, optional
        Where the spool's temporary file goes.
    on_features : callable, optional
        Called with each batch of restricted features read (lists; an update store keeps
        them).

    Returns
    -------
    TiledResult

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.fencing.pipeline import BuildOptions
    >>> from alphafence.zones.database import DatabaseStream
    >>> from alphafence.zones.rules import load_rules
    >>> rules = load_rules()
    >>> scene = str(resources.files("alphafence").joinpath("data/demo-scene.geojson"))
    >>> result = build_tiled(DatabaseStream(scene, rules), rules, BuildOptions(), jobs=1)
    >>> result.features, result.sites, result.stats.fences
    (16, 11, 19)
    """
    auto = jobs is None and not dask
    nbytes = _input_bytes(stream.paths)
    jobs = auto_jobs(0, nbytes) if auto else default_jobs() if jobs is None else max(1, int(jobs))
    result = TiledResult(site_kinds=Counter(), fences=[] if keep else None)
    result.site_objects = [] if keep else None
    t0 = time.perf_counter()
    with ExitStack() as stack:
        pool = None
        if not dask and jobs > 1 and nbytes > WARM_POOL_BYTES:
            pool = start_pool(jobs)  # its imports overlap the reading
            stack.push(stop_on_exit(pool))
        with Spool(spool_dir) as spool:
            # the workers read text sequences too (the main process would read them alone)
            reader = sequence_reader(pool, 2 * jobs, READ_BATCH) if pool is not None else None
            for batch in stream.batches(reader):
                if not isinstance(batch, list):
                    batch.add_to(spool, rules)
                else:
                    if on_features is not None:
                        on_features(batch)
                    widths = feature_widths(batch, rules)
                    spool.add(batch, widths, [spool.class_of(site_class(f)) for f in batch])
                if progress is not None:
                    progress("reading", stream.count, None)
            result.features = len(spool)
            if auto and pool is None:  # the database is small: as many features as it has
                jobs = auto_jobs(result.features, nbytes)
            if target is None:
                target = job_size(result.features)
            plan = plan_jobs(
                spool.bounds, spool.widths, spool.classes, options.join_m, tile_deg, target
            )
            result.jobs = len(plan)
            give_back_memory()  # planning's passing arrays, before the jobs' long run
            t1 = time.perf_counter()
            encoders = tuple(type(w).encode for w in writers)

            def inputs():
                for job in plan:
                    yield JobInput(
                        job.number,
                        spool.records(job.indices),
                        job.spans,
                        rules,
                        spool.rules,
                        spool.origins,
                        options,
                        encoders,
                        keep,
                    )

            if dask:
                outputs = run_dask(inputs(), dask)
            elif jobs > 1 and (len(plan) > 1 or pool is not None):
                outputs = run_processes(inputs(), jobs if pool else min(jobs, len(plan)), pool)
            else:
                outputs = run_local(inputs())
            done = 0
            for out in outputs:
                for writer, payload in zip(writers, out.encoded):
                    writer.write(payload)
                result.sites += out.sites
                result.site_kinds.update(out.site_kinds)
                result.stats.add(out.rows)
                if keep:
                    result.fences.extend(out.fences)
                    result.site_objects.extend(out.site_objects)
                done += out.features
                if progress is not None:
                    progress("fencing", done, result.features)
        result.seconds = {"read": t1 - t0, "fence": time.perf_counter() - t1}
        return result


def give_back_memory() -> None:
    """Hand the heap's free pages back to the system (glibc's ``malloc_trim``; nothing where
    there is none). Planning a large build frees some tens of bytes per feature in arrays the
    allocator would otherwise keep for the rest of the build.

    Examples
    --------
    >>> give_back_memory()
    """
    import ctypes

    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _input_bytes(paths):
    total = 0
    for p in paths:
        try:
            total += os.path.getsize(p)
        except OSError:
            pass
    return total
