"""Issue 13 targets: the country-scale build, ``alphafence build`` as a whole process on 2 cores.

- 133,000 restricted areas: at most 45 s and at most 1.5 GB peak memory;
- 1,000,000 areas: under 10 minutes and under 4 GB peak;
- ``--dask`` on a local cluster of two worker processes: the same fences as the single-process
  build, and its overhead.

The databases are Malta's 133 keep-out areas copied on a grid (``bench/synth_db.py``), generated
once into ``$ALPHAFENCE_CACHE/bench``. Each build is a subprocess pinned to 2 cores; its wall
time is measured, and its peak memory is the peak of the summed RSS of the process and every
descendant (the build's worker processes), sampled from /proc every 50 ms (pages shared between
a parent and its forked workers count once per process: an upper bound, judged against the
target; the peak of the summed PSS, which splits them, is shown too when it is 5 % lower;
a cgroup's peak would need one set up per run). A run is stopped at
twice its time or memory target (at least 120 s): the machine is shared.

The named peer is the single-process build (``--jobs 1``) at the same size, run at sizes up to
133,000 (not at 1,000,000). Until ``alphafence build`` has ``--jobs`` (or ``--dask``), builds run
without it (the CLI's only way, in-process) and the peer is not run; until the reader takes
GeoJSON lines the databases are written as one FeatureCollection.

Sizes other than the defaults (``--scale-sizes 13300`` for a quick run) take the 133,000 target's
rate (45 s per 133,000 areas) and its memory up to 133,000 areas, the 1,000,000 targets above.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

from bench.cli_bench import _command
from bench.synth_db import cached_database, keep_out_areas, write_database

SIZES = (133_000, 1_000_000)
PEER_MAX = 133_000  # the --jobs 1 peer is run at sizes up to this
DASK_AREAS = 13_300
CORES = 2
SAMPLE_S = 0.05
LIMIT_FACTOR = 2.0
MIN_LIMIT_S = 120.0
GB = 1e9


def targets(n):
    """(seconds, bytes) that a build of ``n`` areas must stay within.

    Examples
    --------
    >>> targets(133_000), targets(1_000_000)
    ((45.0, 1500000000.0), (600.0, 4000000000.0))
    >>> targets(13_300)
    (4.5, 1500000000.0)
    """
    if n <= 133_000:
        return 45.0 * n / 133_000, 1.5 * GB
    return 600.0, 4.0 * GB


def build_flags():
    """The options of ``alphafence build --help`` this bench uses (``--jobs``, ``--dask``)."""
    text = subprocess.run(
        _command() + ["build", "--help"], capture_output=True, text=True, check=True
    ).stdout
    return {flag for flag in ("--jobs", "--dask") if flag in text}


def reads_lines(extract):
    """Whether the database reader takes GeoJSON lines (probed on one copy of the areas)."""
    from alphafence.errors import InputError
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "probe.geojsonl"
        n = len(keep_out_areas(extract))
        write_database(extract, n, path, "lines")
        try:
            return len(read_database([path], load_rules()).features) == n
        except (InputError, ValueError):
            return False


# -- one measured process tree -----------------------------------------------------------
def _stat_table():
    """{pid: (ppid, rss bytes, cpu seconds, start time)} of every process, from
    /proc/<pid>/stat."""
    page, tick = os.sysconf("SC_PAGE_SIZE"), os.sysconf("SC_CLK_TCK")
    out = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                f = fh.read().rsplit(b")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        out[int(name)] = (int(f[1]), int(f[21]) * page, (int(f[11]) + int(f[12])) / tick, f[19])
    return out


def _tree(roots, table):
    """The pids of ``roots`` and all their descendants in ``table``."""
    children = {}
    for pid, row in table.items():
        children.setdefault(row[0], []).append(pid)
    seen, todo = set(), [p for p in roots if p in table]
    while todo:
        pid = todo.pop()
        if pid not in seen:
            seen.add(pid)
            todo.extend(children.get(pid, ()))
    return seen


def _pss(pid):
    """The proportional set size of ``pid`` in bytes (None when unreadable)."""
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as fh:
            for line in fh:
                if line.startswith(b"Pss:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def tree_sample(roots, peaks=None):
    """The summed RSS and PSS in bytes of ``roots`` and all their descendants (a process
    without a readable PSS counts its RSS), and each one's CPU seconds so far (user + system)
    by (pid, start time). ``peaks``, a dict, keeps each one's largest RSS by (pid, start time).

    Examples
    --------
    >>> rss, pss, cpu = tree_sample([os.getpid()])
    >>> 0 < pss <= rss, len(cpu)
    (True, 1)
    """
    table = _stat_table()
    seen = _tree(roots, table)
    rss = sum(table[p][1] for p in seen)
    if peaks is not None:
        for p in seen:
            key = (p, table[p][3])
            peaks[key] = max(peaks.get(key, 0), table[p][1])
    pss = sum(x if (x := _pss(p)) is not None else table[p][1] for p in seen)
    return rss, pss, {(p, table[p][3]): table[p][2] for p in seen}


class PeakSampler(threading.Thread):
    """Samples :func:`tree_sample` of ``roots`` every 50 ms until stopped, keeping the peaks
    (``peak``: RSS, ``peak_pss``: PSS held for two samples); calls ``on_limit`` once when the RSS passes ``limit`` bytes
    or ``deadline`` passes."""

    def __init__(self, roots, limit=None, deadline=None, on_limit=None):
        super().__init__(daemon=True)
        self.roots, self.limit, self.deadline, self.on_limit = (
            list(roots),
            limit,
            deadline,
            on_limit,
        )
        self.peak, self.peak_pss, self.stopped_why = 0, 0, None
        self.cpu = {}  # (pid, start time): user + system seconds last seen
        self.peaks = {}  # (pid, start time): largest RSS seen
        self._done = threading.Event()

    def run(self):
        last = 0
        while not self._done.is_set():
            rss, pss, cpu = tree_sample(self.roots, self.peaks)
            self.cpu.update(cpu)
            # a PSS sum read across a fork can count the parent whole and its child's share:
            # a peak must hold for two samples
            self.peak, self.peak_pss = max(self.peak, rss), max(self.peak_pss, min(last, pss))
            last = pss
            if self.stopped_why is None:
                if self.limit is not None and self.peak > self.limit:
                    self.stopped_why = f"stopped above {self.limit / GB:.1f} GB"
                elif self.deadline is not None and time.monotonic() > self.deadline:
                    self.stopped_why = "stopped at the time limit"
                if self.stopped_why and self.on_limit:
                    self.on_limit()
            self._done.wait(SAMPLE_S)

    def stop(self):
        """Stop sampling and wait for the thread."""
        self._done.set()
        self.join()


def _pin():
    """In the child: run on ``CORES`` of the CPUs this process may use."""
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, cpus[:CORES])


def measure(argv, limit_s, limit_bytes, extra_roots=()):
    """Run ``argv`` pinned to 2 cores in a session of its own; returns a dict: ``wall`` s,
    ``cpu`` s (user + system of every process in the trees, as last sampled), ``peak`` bytes (with
    ``extra_roots``' trees), ``rc`` and ``why`` (None, or why it was stopped)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=_pin,
        start_new_session=True,
    )

    def kill():
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass

    sampler = PeakSampler(
        [proc.pid, *extra_roots], limit_bytes, time.monotonic() + limit_s, on_limit=kill
    )
    sampler.start()
    err = proc.stderr.read()  # until the build (and anything holding its stderr) ends
    _, status, _ = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    sampler.stop()
    kill()  # any worker it left behind
    return {
        "wall": wall,
        "cpu": sum(sampler.cpu.values()),
        "peak": sampler.peak,
        "pss": sampler.peak_pss,
        "peaks": sorted(sampler.peaks.values(), reverse=True),
        "main_peak": max(
            (v for (pid, _), v in sampler.peaks.items() if pid == proc.pid), default=0
        ),
        "rc": proc.returncode,
        "why": sampler.stopped_why,
        "err": err.decode(errors="replace").strip().splitlines()[-1:] or [""],
    }


def _result(m):
    """A measurement as the result column."""
    text = f"{m['wall']:.1f} s, {m['peak'] / GB:.2f} GB peak, cpu {m['cpu']:.0f} s"
    if m["pss"] < 0.95 * m["peak"]:  # forked workers share pages: RSS counts them per process
        text += f" (PSS {m['pss'] / GB:.2f} GB)"
    if m["why"]:
        done = f", {m['written'] / 1e6:.0f} MB of output written" if m.get("written") else ""
        return f"{text} ({m['why']}{done})"
    if m["rc"]:
        return f"{text} (exit {m['rc']}: {m['err'][0][:60]})"
    return text


def _failed(m):
    """Whether a measured build was stopped or failed."""
    return bool(m["why"] or m["rc"])


def _short(m):
    """A measurement as the peer column."""
    text = f"{m['wall']:.1f} s, {m['peak'] / GB:.2f} GB"
    return f"{text} (stopped)" if m["why"] else f"{text} (exit {m['rc']})" if m["rc"] else text


# -- the rows ------------------------------------------------------------------------------
def run(osm, Row, console, sizes=SIZES):
    """A row per size (with its --jobs 1 peer up to 133,000 areas) and the --dask row."""
    flags = build_flags()
    fmt = "lines" if reads_lines(osm) else "collection"
    base = len(keep_out_areas(osm))
    if "--jobs" not in flags:
        console.print("scale: `alphafence build` has no --jobs yet: each size built as today")
    if fmt == "collection":
        console.print(
            "scale: the reader takes no GeoJSON lines yet: databases as FeatureCollections"
        )
    rows, runs = [], {}
    with tempfile.TemporaryDirectory(prefix="scale-bench-") as tmp:

        def build(n, jobs=None, dask=None, extra_roots=()):
            db, gen = cached_database(osm, n, fmt)
            if gen:
                size = db.stat().st_size / 1e6
                console.print(f"scale: generated {n:,} areas in {gen:.1f} s ({size:.0f} MB): {db}")
            out = Path(tmp) / f"{n}-{'dask' if dask else f'jobs{jobs}'}.geojson"
            argv = _command() + ["build", str(db), "-o", str(out), "-q"]
            argv += ["--jobs", str(jobs)] if jobs else []
            argv += ["--dask", dask] if dask else []
            t, m = targets(n)
            m = measure(argv, max(LIMIT_FACTOR * t, MIN_LIMIT_S), LIMIT_FACTOR * m, extra_roots)
            m["out"] = out
            # a stopped build leaves its output's temporary file: how far it got
            m["written"] = sum(f.stat().st_size for f in out.parent.glob(f".{out.name}.*.tmp"))
            console.print(f"scale: {' '.join(argv[1:])}: {_result(m)}")
            return m

        for n in sizes:
            jobs = CORES if "--jobs" in flags else None
            m = runs[(n, jobs)] = build(n, jobs)
            t, mem = targets(n)
            peer, ratio = "-", "-"
            if jobs and n <= PEER_MAX:
                p = runs[(n, 1)] = build(n, 1)
                peer = f"--jobs 1 {_short(p)}"
                ratio = "-" if _failed(m) or _failed(p) else f"{p['wall'] / m['wall']:.2f}x"
            elif jobs:
                peer = "--jobs 1 not run at this size"
            how = f"--jobs {jobs}" if jobs else "no --jobs yet"
            rows.append(
                Row(
                    f"scale: build {n:,} areas ({-(-n // base):,} copies of Malta's {base} "
                    f"keep-out areas), {CORES} cores, {how}",
                    _result(m),
                    f"<= {t:.3g} s, <= {mem / GB:.1f} GB",
                    peer,
                    ratio,
                    not _failed(m) and m["wall"] <= t and m["peak"] <= mem,
                )
            )
        rows.append(dask_row(Row, console, flags, build, runs))
    return rows


def _fences(path):
    """The fences of a build's output as a Counter of (site_id, kind, normalised WKB)."""
    import shapely

    from alphafence.fencefiles.fence_geojson import read_fences

    return Counter(
        (f.site_id, f.kind, shapely.to_wkb(shapely.normalize(f.geometry)))
        for f in read_fences(path)
    )


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def dask_row(Row, console, flags, build, runs):
    """The --dask build of 13,300 areas on a local scheduler and two single-threaded worker
    processes, against --jobs 1: same fences, overhead as the ratio."""
    name = f"scale: --dask, 2 local worker processes, {DASK_AREAS:,} areas"
    if importlib.util.find_spec("distributed") is None:
        return Row(name, "not run: dask not installed", "same fences as --jobs 1", "-", "-", True)
    if "--dask" not in flags:
        return Row(name, "not run: no --dask yet", "same fences as --jobs 1", "-", "-", True)
    try:
        with local_cluster() as (addr, pids):
            d = build(DASK_AREAS, dask=addr, extra_roots=pids)
    except (OSError, TimeoutError) as exc:
        return Row(name, f"no cluster: {exc}"[:80], "same fences as --jobs 1", "-", "-", False)
    s = runs.get((DASK_AREAS, 1)) or build(DASK_AREAS, 1)
    if _failed(d) or _failed(s):
        same, verdict = False, "a build failed: see above"
    else:
        a, b = _fences(d["out"]), _fences(s["out"])
        same = a == b
        verdict = (
            f"same {sum(a.values()):,} fences"
            if same
            else (
                f"fences DIFFER ({sum((a - b).values())} only in --dask, "
                f"{sum((b - a).values())} only in --jobs 1)"
            )
        )
    return Row(
        name,
        f"{d['wall']:.1f} s, {d['peak'] / GB:.2f} GB peak with the cluster, {verdict}",
        "same fences as --jobs 1",
        f"--jobs 1 {_short(s)}",
        "-" if _failed(d) or _failed(s) else f"{d['wall'] / s['wall']:.2f}x overhead",
        same,
    )


@contextlib.contextmanager
def local_cluster(workers=2):
    """A Dask scheduler and ``workers`` single-threaded worker processes (each pinned to the
    bench's cores), started with Dask's own command: ``(address, their pids)``."""
    import distributed

    dask = Path(sys.executable).with_name("dask")
    addr = f"tcp://127.0.0.1:{_free_port()}"
    common = ["--no-dashboard"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "start_new_session": True}
    procs = [subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port",
                               addr.rsplit(":", 1)[1], *common], **quiet)]  # fmt: skip
    try:
        for _ in range(workers):
            procs.append(subprocess.Popen([str(dask), "worker", addr, "--nworkers", "1",
                                           "--nthreads", "1", *common], preexec_fn=_pin,
                                          **quiet))  # fmt: skip
        with distributed.Client(addr, timeout=60) as client:
            client.wait_for_workers(workers, timeout=120)
        yield addr, [p.pid for p in procs]
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
