"""The parts of a live source in flight that are not its polling
(:class:`~alphafence.monitor.live.LiveSource`): what it is asked and how often
(:class:`LiveOptions`), the worker process it fences in, a document source's signature, the
thread switch interval while a fence set is rebuilt, and one line for any exception."""

from __future__ import annotations

import asyncio
import contextlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

SWITCH_S = 0.0002  # the interpreter's thread switch interval while a fence set is rebuilt


@dataclass
class LiveOptions:
    """What the monitor asks a live source, and how often.

    Attributes
    ----------
    source : SourceOptions
    rules : Rules
        What a plain GeoJSON feature restricts.
    build : BuildOptions
        How zones are fenced.
    refresh_s : float
        Seconds between answers.
    stale_after_s : float or None
        Without a good answer this long the source is stale (default: 3 refreshes).
    radius_m : float
        The area asked around the vehicle (and around each mission waypoint).
    announce_s : float
        A zone whose window starts within this many seconds is announced.
    trusted_keys : tuple of str
        PEM public keys: a source that is one document (a signed fence bundle on a web
        server, not a collection) must come with ``URL.sig.json`` signed by one of them
        (:mod:`alphafence.fencing.bundle`), checked at every answer.
    from_file : bool
        The monitor started from a fence file (an offline copy, even an empty one). False: from
        the source alone, nothing is known to be in force until its first complete answer
        (:attr:`LiveSource.known`), and no position is reported CLEAR before it.
    """

    source: object
    rules: object
    build: object
    refresh_s: float = 30.0
    stale_after_s: float | None = None
    radius_m: float = 5000.0
    announce_s: float = 600.0
    trusted_keys: tuple = ()  # a document source (a fence bundle): its signature must verify
    from_file: bool = True  # started from a fence file (an offline copy): what is in force is known

    @property
    def stale_s(self) -> float:
        return self.stale_after_s if self.stale_after_s is not None else 3.0 * self.refresh_s


async def verify(http, options, answer) -> None:
    """The document's detached signature (``URL.sig.json``) checked against the trusted
    keys (in a worker thread: files and hashing): SourceError when it is not authentic."""
    import tempfile
    from pathlib import Path

    from alphafence.errors import InputError, SourceError
    from alphafence.fencing.bundle import SUFFIX
    from alphafence.fencing.bundle import verify as check_bundle
    from alphafence.sources.request import fetch_bytes

    signature = await fetch_bytes(http, options.source, answer.url + SUFFIX)

    def check():
        with tempfile.TemporaryDirectory(prefix="alphafence-") as tmp:
            doc = Path(tmp) / "fences.geojson"
            doc.write_bytes(answer.raw)
            Path(str(doc) + SUFFIX).write_bytes(signature)
            check_bundle(doc, options.trusted_keys)

    try:
        await asyncio.to_thread(check)
    except InputError as exc:
        raise SourceError(answer.url, f"not authentic, not applied: {exc.message}") from None


def pool():
    """The fencing worker: one process, spawned (not forked: the monitor has threads)."""
    import multiprocessing

    from alphafence.fencing.zone_fences import worker_start

    context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(1, mp_context=context, initializer=worker_start)


def one_line(exc) -> str:
    """One line for any exception: its type and its first 300 characters."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300]


@contextlib.contextmanager
def short_switches(interval_s: float = SWITCH_S):
    """The interpreter's thread switch interval shortened while a worker thread rebuilds the
    fence set: a position check waits at most this long for the interpreter between its GEOS
    calls (at the default 5 ms the checks during a rebuild are several times slower)."""
    import sys

    old = sys.getswitchinterval()
    sys.setswitchinterval(interval_s)
    try:
        yield
    finally:
        sys.setswitchinterval(old)


def read_answer(options, features, known):
    """The worker's job (:func:`alphafence.fencing.zone_fences.read_answer`) with the options'
    source, rules and build options: a picklable call for the process pool."""
    from alphafence.fencing.zone_fences import read_answer

    return read_answer(options.source.url, features, options.rules, options.build, known)
