"""Live sources (``monitor --source``): what an answer costs, and what fencing it costs the
position checks.

- Refresh cost at 100 and 10,000 zones in the window: one answer of synthetic ED-318 zones
  (200 m squares on a grid over Malta) read and fenced as the monitor's worker does it
  (:func:`alphafence.fencing.zone_fences.read_answer`: hash, read, fence each new zone), the
  first time (every zone new) and again (every zone known: hashed only). Peer: the same zones
  as a file, read and built by ``alphafence build``'s library calls (``read_ed269_doc`` and
  ``build_fences``, sites grouped): the first refresh should cost no more than a build of its
  zones (target <= 1.5x), an unchanged one a small part of it (<= 0.2x).
- Check p99 during an in-flight build: the monitor's position check (``FenceSet.check`` on the
  Malta fences, 50 positions a second on an event loop) timed for 5 s alone, then for 5 s while
  a live source fences 1,000 new zones in its worker process (spawned, niced) and the fence set
  is rebuilt in a worker thread and swapped in, as the monitor does. Target: p99 within 1.1x of
  the p99 alone. The checks' lateness (how late each ran after it was due: the event loop's
  delay) is reported beside it.
"""

from __future__ import annotations

import asyncio
import math
import multiprocessing
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.zone_fences import read_answer, worker_start
from alphafence.geo.frame import LocalFrame
from alphafence.zones.database import read_database
from alphafence.zones.ed269 import read_ed269_doc
from alphafence.zones.rules import load_rules

CENTRE = (14.45, 35.90)  # lon, lat
RATE_HZ = 50.0
PHASE_S = 5.0


def zones(n: int, spacing_m: float = 400.0) -> list:
    """``n`` ED-318 keep-out zones, 200 m squares on a grid around Malta."""
    frame = LocalFrame(*CENTRE)
    side = math.ceil(math.sqrt(n))
    out = []
    for k in range(n):
        x, y = (k % side - side / 2) * spacing_m, (k // side - side / 2) * spacing_m
        xs, ys = [x, x + 200, x + 200, x, x], [y, y, y + 200, y + 200, y]
        lon, lat = frame.to_wgs84(xs, ys)
        ring = [[round(float(a), 7), round(float(b), 7)] for a, b in zip(lon, lat)]
        out.append({"type": "Feature", "id": f"Z{k}", "geometry": {"type": "Polygon",
                    "coordinates": [ring]}, "properties": {
                        "identifier": f"Z{k}", "name": f"closure {k}", "type": "PROHIBITED",
                        "zoneAuthority": [{"name": "bench"}], "reason": ["EMERGENCY"],
                        "verticalLayer": {"upper": 120, "upperReference": "AGL", "lower": 0,
                                          "lowerReference": "AGL", "uom": "m"}}})  # fmt: skip
    return out


def refresh_cost(Row) -> list:
    rules, options, rows = load_rules(), BuildOptions(), []
    for n in (100, 10_000):
        features = zones(n)
        t0 = time.perf_counter()
        entries, bad, fenced = read_answer("bench", features, rules, options, set())
        first = time.perf_counter() - t0
        known = {e[1].hash for e in entries}
        t0 = time.perf_counter()
        again, _, refenced = read_answer("bench", features, rules, options, known)
        second = time.perf_counter() - t0
        assert not bad and len(entries) == n and not refenced and len(again) == n
        t0 = time.perf_counter()
        doc = {"type": "FeatureCollection", "features": features}
        read = read_ed269_doc("bench", doc, rules, [], Counter())
        build_fences(read, rules, options)
        peer = time.perf_counter() - t0
        rows.append(Row(f"live refresh, {n:,} new zones read and fenced", f"{first:.2f} s",
                        "<= 1.5x a build of them", f"file build {peer:.2f} s",
                        f"{first / peer:.2f}x", first <= 1.5 * peer, first, "s", peer))  # fmt: skip
        rows.append(Row(f"live refresh, {n:,} zones unchanged (hashed only)", f"{second:.3f} s",
                        "<= 0.2x a build of them", f"file build {peer:.2f} s",
                        f"{second / peer:.3f}x", second <= 0.2 * peer, second, "s", peer))  # fmt: skip
    return rows


def check_p99(osm, Row) -> list:
    rules = load_rules()
    db = read_database([osm], rules)
    built = build_fences(db.features, rules, BuildOptions())
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in built.fences]
    frame = LocalFrame(14.51, 35.89)
    fences = FenceSet(records, frame=frame)
    fences.index()
    features = zones(1000)
    alone, late_alone = asyncio.run(_checks(fences, None))
    busy, late_busy = asyncio.run(_checks(fences, _fencing(features)))
    _, _, fenced = read_answer("bench", features, rules, BuildOptions(), set())
    live = [r for rs in fenced.values() for r in rs]
    t0 = time.perf_counter()
    FenceSet(records + live, frame=frame).index()
    swap_s = time.perf_counter() - t0
    swapping, late_swap = asyncio.run(_checks(fences, _swapping(records + live, frame)))
    p = [np.percentile(d, 99) * 1e6 for d in (alone, busy, swapping)]
    lag = [np.percentile(d, 99) * 1e3 for d in (late_alone, late_busy, late_swap)]
    n = len(records)
    return [
        Row(f"check p99 while 1,000 live zones are fenced in the worker ({n} Malta fences)",
            f"{p[1]:.1f} us", "<= 1.1x without", f"without {p[0]:.1f} us",
            f"{p[1] / p[0]:.2f}x", p[1] <= 1.1 * p[0], p[1], "us", p[0]),
        Row("check lateness p99 (event loop delay) while they are fenced",
            f"{lag[1]:.2f} ms", "reported", f"without {lag[0]:.2f} ms",
            f"{lag[1] / max(lag[0], 1e-6):.2f}x", True, lag[1], "ms", lag[0]),
        Row(f"fence set swapped in ({n} + {len(live)} fences, a worker thread)",
            f"{swap_s * 1e3:.0f} ms", "reported", "-", "-", True, swap_s * 1e3, "ms"),
        Row("check p99 while the fence set is rebuilt in a worker thread",
            f"{p[2]:.1f} us", "reported", f"without {p[0]:.1f} us",
            f"{p[2] / p[0]:.2f}x", True, p[2], "us", p[0]),
    ]  # fmt: skip


async def _checks(fences, work):
    """Checks at RATE_HZ for PHASE_S (while ``work``, an async function of a stop event,
    runs): each check's duration and lateness, in seconds."""
    rng = np.random.default_rng(7)
    loop = asyncio.get_running_loop()
    durations, late = [], []
    stop = asyncio.Event()
    task = None
    if work is not None:
        started = asyncio.Event()
        task = asyncio.create_task(work(stop, started))
        await started.wait()
    t_next = loop.time()
    end = t_next + PHASE_S
    while loop.time() < end:
        t_next += 1.0 / RATE_HZ
        await asyncio.sleep(max(0.0, t_next - loop.time()))
        late.append(max(0.0, loop.time() - t_next))
        x, y = rng.uniform(-3000, 3000, 2)
        t0 = time.perf_counter()
        fences.check(float(x), float(y), 30.0, 7.0, 7.0, 150.0)
        durations.append(time.perf_counter() - t0)
    stop.set()
    if task is not None:
        await task
    return durations, late


def _fencing(features):
    """Zones fenced over and over in a spawned, niced worker process, as the monitor's."""

    async def work(stop, started):
        loop = asyncio.get_running_loop()
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=context, initializer=worker_start) as pool:
            await loop.run_in_executor(pool, worker_start)  # the process is up
            started.set()
            rules, options = load_rules(), BuildOptions()
            while not stop.is_set():
                await loop.run_in_executor(
                    pool, read_answer, "bench", features, rules, options, set()
                )

    return work


def _swapping(records, frame):
    """The fence set rebuilt over and over in a worker thread, as the monitor swaps it."""

    def build():
        fs = FenceSet(records, frame=frame)
        fs.index()

    async def work(stop, started):
        started.set()
        while not stop.is_set():
            await asyncio.to_thread(build)

    return work


def run(osm, Row) -> list:
    return refresh_cost(Row) + check_p99(osm, Row)


if __name__ == "__main__":
    import sys

    from bench.build_bench import Row

    for r in run(sys.argv[1], Row):
        print(r.name, "|", r.result, "|", r.peer, "|", r.ratio, "|", r.ok)
