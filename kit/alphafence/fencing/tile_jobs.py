"""Tile jobs run here, in worker processes or on a Dask cluster, with results in order.

A job carries everything it needs (its features' spool records, the rules, the options), so
a worker on another machine needs no shared disk. It returns its fences already encoded for
each output, and a few numbers per fence for the summary, so the main process only writes.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from alphafence.fencing.fences import fence_sites
from alphafence.fencing.sites import regions_sites
from alphafence.fencing.spool import Spool

PRELOAD = [
    "alphafence.fencing.tile_jobs",
    "alphafence.fencing.read_jobs",
    "alphafence.fencefiles.fence_geojson",
    "alphafence.fencefiles.fence_stream",
    "scipy.spatial",
    "scipy.sparse.csgraph",
]


@dataclass
class JobInput:
    """What a worker needs for one tile job.

    Attributes
    ----------
    number : int
    records : list of bytes
        Spool records, region after region.
    spans : list of tuple
        ``(start, end)`` of each region in ``records``.
    rules : Rules
        For the widths of points and lines.
    rule_table, origins : list
        The spool's tables the records refer to.
    options : BuildOptions
    encoders : tuple
        ``encode(features) -> payload`` per output (run here, written by the main process).
    keep : bool
        Also return the Fence and Site objects (for outputs that need them all at once).
    """

    number: int
    records: list
    spans: list
    rules: object
    rule_table: list
    origins: list
    options: object
    encoders: tuple = ()
    keep: bool = False


@dataclass
class JobOutput:
    """What a tile job made.

    Attributes
    ----------
    number : int
    features : int
        Restricted features fenced.
    encoded : list
        One payload per encoder.
    rows : list of tuple
        ``(category, kind, vertices, area_m2, repaired, site_id, circle, items)`` per fence.
    sites : int
    site_kinds : list of tuple
        ``(category, kind)`` per site.
    fences, site_objects : list, optional
        When the job was asked to keep them.
    """

    number: int
    features: int
    encoded: list
    rows: list
    sites: int
    site_kinds: list = field(default_factory=list)
    fences: list | None = None
    site_objects: list | None = None


def fence_rows(fences):
    """The numbers the build's summary needs per fence (see :attr:`JobOutput.rows`): each
    fence's ``vertices``, ``area_m2`` and ``item_count``, counted for all of them at once."""
    from alphafence.fencefiles.fence_geojson import fence_numbers
    from alphafence.mavlink.items import item_counts

    fences = list(fences)
    vertices, areas = fence_numbers(fences)
    return [
        (
            f.category,
            f.kind,
            n,
            area,
            f.repaired,
            f.site_id,
            f.circle is not None,
            items,
            f.growth,
        )  # fmt: skip
        for f, n, area, items in zip(fences, vertices, areas, item_counts(fences))
    ]


def run_job(job: JobInput) -> JobOutput:
    """Group one job's regions into sites and fence them (the untiled build's own steps).

    Parameters
    ----------
    job : JobInput

    Returns
    -------
    JobOutput
    """
    from alphafence.fencefiles.fence_geojson import fence_features

    features = Spool.decode(job.records, job.rule_table, job.origins)
    sites = regions_sites(features, job.spans, job.rules, job.options.join_m)
    sites.sort(key=lambda s: (s.category, s.site_id))
    fences = fence_sites(sites, job.options)
    encoded = []
    if job.encoders:
        docs = fence_features(fences)
        encoded = [encode(docs) for encode in job.encoders]
    return JobOutput(
        job.number,
        len(features),
        encoded,
        fence_rows(fences),
        len(sites),
        [(s.category, s.kind) for s in sites],
        fences if job.keep else None,
        sites if job.keep else None,
    )


def _in_order(submit, results_of, jobs, window):
    """Submit jobs at most ``window`` ahead and yield their results in job order."""
    pending = deque()
    it = iter(jobs)
    for job in it:
        pending.append(submit(job))
        if len(pending) >= window:
            break
    while pending:
        yield results_of(pending.popleft())
        for job in it:
            pending.append(submit(job))
            break


def run_local(jobs):
    """Jobs one after the other in this process."""
    for job in jobs:
        yield run_job(job)


def start_pool(workers: int):
    """A pool of ``workers`` worker processes forked from a server that has imported the
    fencing code once, started now: a build starts it before reading its database, so the
    imports run on a core the reading leaves idle.

    Returns
    -------
    concurrent.futures.ProcessPoolExecutor
    """
    import multiprocessing
    import signal
    import threading
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import forkserver, resource_tracker

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    # Ctrl-C is the main process's: it cancels the jobs not started (:func:`stop_pool`), and
    # the workers, which ignore it (else each printed a traceback), finish the one they hold
    # (a job is about a second) and leave. The forkserver is started ignoring it, which it
    # keeps through Python's start and its imports, and its workers inherit.
    # A Ctrl-C that comes while the server starts is held (blocked), not lost to SIG_IGN, and
    # raised here once the handler is back; the server, and any worker, is then stopped. (A
    # Ctrl-C that another thread takes in the window, as a progress bar's refresh thread can
    # on a terminal, is still lost: the window is the server's spawn, some milliseconds.) The
    # resource tracker is started first: starting it unblocks Ctrl-C, which would let a held
    # one through to SIG_IGN.
    main = threading.current_thread() is threading.main_thread()
    pool = None
    try:
        resource_tracker.ensure_running()
        if main:
            held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            forkserver.ensure_running()
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)
                signal.pthread_sigmask(signal.SIG_SETMASK, held)
        pool = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=ctx,
            initializer=signal.signal,
            initargs=(signal.SIGINT, signal.SIG_IGN),
        )
        for _ in range(workers):
            pool.submit(int)  # a task that starts a worker (it waits for the server's preload)
    except BaseException:
        if pool is None:
            _stop_server()
        else:
            stop_pool(pool, server=True)
        raise
    return pool


def stop_pool(pool, server: bool = False, now: bool = False) -> None:
    """Stop a :func:`start_pool` pool: jobs not started are cancelled, the workers leave.

    Parameters
    ----------
    pool : concurrent.futures.ProcessPoolExecutor
    server : bool
        Interrupted while the pool was starting: the forkserver is stopped too (a worker it
        had yet to fork would start after this process is gone and fail loudly; the next pool
        starts a new server).
    now : bool
        Interrupted (Ctrl-C): the workers are killed in their jobs, which write nothing of
        their own, rather than waited for (a job is about a second).
    """
    if server:
        _stop_server()
    if now or server:
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            try:
                process.kill()
            except (OSError, ValueError):  # gone already, or closed
                pass
    pool.shutdown(wait=True, cancel_futures=True)


def _stop_server() -> None:
    """Stop the forkserver, if one runs: first stopped, so that it forks no more; then its
    workers, then itself, reaped, so that the next pool in this process starts a new one."""
    import os
    import signal
    from multiprocessing import forkserver

    pid = getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)
    if not pid:
        return
    try:
        os.kill(pid, signal.SIGSTOP)
        with open(f"/proc/{pid}/task/{pid}/children") as fh:
            for child in fh.read().split():
                os.kill(int(child), signal.SIGKILL)
    except OSError:
        pass  # gone already, or no /proc (not Linux)
    try:
        os.kill(pid, signal.SIGKILL)
    except OSError:
        pass
    try:  # multiprocessing's own stop: reaps it and forgets it (else a later start fails)
        forkserver._forkserver._stop()
    except (AttributeError, OSError):
        pass


def stop_on_exit(pool):
    """An ``ExitStack.push`` callback that stops ``pool`` on leaving, at once when the way
    out is Ctrl-C (:func:`stop_pool`)."""

    def stop(kind, value, traceback):
        stop_pool(pool, now=kind is not None and issubclass(kind, KeyboardInterrupt))

    return stop


def run_processes(jobs, workers: int, pool=None):
    """Jobs in ``workers`` worker processes (forkserver), results in job order, at most two
    jobs per worker in flight (so memory holds a few tiles, not the country).

    Parameters
    ----------
    jobs : iterable of JobInput
    workers : int
    pool : concurrent.futures.ProcessPoolExecutor, optional
        One :func:`start_pool` started (shut down here when the jobs are done).

    Yields
    ------
    JobOutput
    """
    owned, pool = pool is None, pool or start_pool(workers)
    try:
        yield from _in_order(
            lambda job: pool.submit(run_job, job), lambda fut: fut.result(), jobs, 2 * workers
        )
    except GeneratorExit:  # the consumer stopped: its owner stops the pool it gave, as it left
        if owned:
            stop_pool(pool)
        raise
    except BaseException as exc:  # Ctrl-C or an error: no more jobs
        stop_pool(pool, now=isinstance(exc, KeyboardInterrupt))
        raise
    pool.shutdown(wait=True)


def run_dask(jobs, address: str, connect_timeout: float = 10.0):
    """Jobs on a ``dask.distributed`` cluster, results in job order.

    Parameters
    ----------
    jobs : iterable of JobInput
    address : str
        The scheduler's address, e.g. ``tcp://10.0.0.5:8786``.
    connect_timeout : float
        Seconds to wait for the scheduler.

    Yields
    ------
    JobOutput

    Raises
    ------
    alphafence.errors.InputError
        No scheduler answers at ``address``, or it has no workers.
    """
    from alphafence.errors import InputError, need

    need(("distributed", f"--dask {address}"))
    from distributed import Client

    try:
        # jobs go to the workers and fences come back directly, not through the scheduler
        # (which kept some 1.3 MB per job it passed on: over 1 GB in a 2,000,000-area build)
        client = Client(
            address, timeout=connect_timeout, set_as_default=False, direct_to_workers=True
        )
    except OSError as exc:
        raise InputError("--dask", f"no Dask scheduler at {address} ({exc})") from None
    with client:
        workers = len(client.scheduler_info().get("workers", {}))
        if not workers:
            raise InputError("--dask", f"the Dask scheduler at {address} has no workers")
        yield from _in_order(
            lambda job: client.submit(run_job, client.scatter(job, hash=False), pure=False),
            lambda fut: fut.result(),
            jobs,
            2 * workers,
        )
