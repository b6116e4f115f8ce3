"""Towards the planet: 1,000,000 and 2,000,000 synthetic areas, built with ``--jobs 2`` and on a
local dask.distributed cluster (a scheduler and two single-threaded workers started with
Dask's own ``dask scheduler`` / ``dask worker``), each pinned to 2 cores. Not in the default
run (some 25 minutes on 2 cores): ``python -m bench --only planet``.

Wall time, and the peak of the summed memory of every process (the build, its workers, and for
Dask the scheduler and the workers), sampled from /proc every 50 ms (``scale_bench.measure``).
The output is GeoJSON lines, written as jobs complete (never gathered). Targets: time linear in
the areas (2,000,000 within 2.2x of 1,000,000) and memory flat (2,000,000's peak within 1.2x
of 1,000,000's), for each engine.
"""

from __future__ import annotations

import importlib.util
import tempfile
from pathlib import Path

from bench.cli_bench import _command
from bench.scale_bench import GB, _result, local_cluster, measure
from bench.synth_db import cached_database

SIZES = (1_000_000, 2_000_000)
TIME_RATIO = 2.2
MEMORY_RATIO = 1.2
LIMIT_S = 3600.0
LIMIT_BYTES = 12 * GB


def run(extract, Row, console, sizes=SIZES):
    """A row per engine and size, then the two ratios per engine."""
    engines = ["jobs"]
    if importlib.util.find_spec("distributed") is not None:
        engines.append("dask")
    rows, runs = [], {}
    with tempfile.TemporaryDirectory(prefix="planet-bench-") as tmp:
        for n in sizes:
            db, gen = cached_database(extract, n, "lines")
            if gen:
                console.print(f"planet: generated {n:,} areas in {gen:.0f} s: {db}")
            for engine in engines:
                out = Path(tmp) / f"{n}-{engine}.geojsonl"
                argv = [*_command(), "build", str(db), "-o", str(out), "-q"]
                if engine == "jobs":
                    m = measure([*argv, "--jobs", "2"], LIMIT_S, LIMIT_BYTES)
                else:
                    with local_cluster() as (addr, pids):
                        m = measure([*argv, "--dask", addr], LIMIT_S, LIMIT_BYTES, pids)
                m["fences"] = sum(1 for _ in open(out, "rb")) if out.exists() else 0
                out.unlink(missing_ok=True)
                runs[(engine, n)] = m
                how = "--jobs 2" if engine == "jobs" else "--dask, 2 local workers"
                console.print(f"planet: {n:,} areas, {how}: {_result(m)}; {_split(m)}")
                ok = not (m["why"] or m["rc"])
                rows.append(Row(f"planet: build {n:,} areas, {how}",
                                f"{_result(m)}; {_split(m)}, {m['fences']:,} fences ({n / m['wall']:,.0f} "
                                "areas/s)", "-", "-", "-", ok, m["wall"], "s"))  # fmt: skip
        if len(sizes) == 2:
            small, large = sizes
            for engine in engines:
                a, b = runs[(engine, small)], runs[(engine, large)]
                t, mem = b["wall"] / a["wall"], b["peak"] / a["peak"]
                how = "--jobs 2" if engine == "jobs" else "--dask"
                rows.append(Row(f"planet: {how} time, {large:,} against {small:,}", f"{t:.2f}x",
                                f"<= {TIME_RATIO}x", f"{a['wall']:.0f} s", f"{t:.2f}x",
                                t <= TIME_RATIO))  # fmt: skip
                rows.append(Row(f"planet: {how} peak memory, {large:,} against {small:,}",
                                f"{b['peak'] / GB:.2f} GB", f"<= {MEMORY_RATIO}x",
                                f"{a['peak'] / GB:.2f} GB", f"{mem:.2f}x",
                                mem <= MEMORY_RATIO))  # fmt: skip
    return rows


def _split(m):
    """The peak by process: the build's own, and the largest others' (workers, scheduler).

    Examples
    --------
    >>> _split({"main_peak": 3e8, "peaks": [4e8, 3e8, 2e8, 1e7]})
    'build process 0.30 GB, others up to 0.40, 0.20, 0.01 GB'
    """
    others = list(m["peaks"])
    if m["main_peak"] in others:
        others.remove(m["main_peak"])
    text = ", ".join(f"{p / GB:.2f}" for p in others[:4])
    return f"build process {m['main_peak'] / GB:.2f} GB" + (
        f", others up to {text} GB" if others else ""
    )
