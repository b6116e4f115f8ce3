"""Live sources (``monitor --source``): what an answer costs, and what fencing it costs the
position checks.

- Refresh cost at 100 and 10,000 zones in the window: one answer of synthetic ED-318 zones
  (200 m squares on a grid over Malta) read and fenced as the monitor's worker does it
  (:func:`alphafence.fencing.zone_fences.read_answer`: hash, read, fence each new zone), the
  first time (every zone new) and again (every zone known: hashed only). Peer: the same zones
  as a file, read and built by ``alphafence build``'s library calls (``read_ed269_doc`` and
  ``build_fences``, sites grouped): the first refresh should cost no more than a build of its
  zones (target <= 1.5x), an unchanged one a small part of it (<= 0.2x).
- Zone served to onboard: copter SITL at speedup 1 flying the Malta leg west at 5 m/s with the
  monitor (``--onboard rolling``, the copter profile) following pygeoapi over PostGIS (started
  on loopback as the tests start them) every 10 s; three keep-out zones are inserted 7 s apart,
  each 250 m ahead and 120 m to the side of the vehicle (within the rolling fence's radius, off
  its path). Measured: from each insert to the verified upload of a rolling fence compiled
  after its fences were swapped in. Target: at most one refresh period plus 3 s.
- Check p99 during an in-flight build: the monitor's position check (``FenceSet.check`` on the
  Malta fences, 100 positions a second on an event loop) timed for 5 s alone, then while a live
  source's worker process (spawned, niced) fences five answers of 1,000 new zones one after
  the other, the answers sent (their pages' bytes) and the fences received as the monitor
  does. Target: p99 within 1.1x of the p99 alone (three rounds, alone and busy interleaved:
  the median p99 of each). The checks' lateness (how late each ran after it was due: the
  event loop's delay) is reported beside it; and, apart, the fence set's rebuild in a worker
  thread (the swap, once per change) and the checks' p99 while it runs.
"""

from __future__ import annotations

import asyncio
import json
import math
import multiprocessing
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.zone_fences import read_answer, unpack, worker_start
from alphafence.geo.frame import LocalFrame
from alphafence.zones.database import read_database
from alphafence.zones.ed269 import read_ed269_doc
from alphafence.zones.rules import load_rules

CENTRE = (14.45, 35.90)  # lon, lat
RATE_HZ = 100.0  # checks a second (a 50 Hz link at speedup 2): samples for the p99
PHASE_S = 5.0
BUILDS = 5  # answers of 1,000 new zones fenced while the checks are timed
ROUNDS = 3  # alone, then busy, this many times: the median p99 of each is compared


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
    pages = [  # the answer as it comes, 500 zones a page: the monitor hands these to its worker
        json.dumps({"type": "FeatureCollection", "features": features[k : k + 500]}).encode()
        for k in range(0, len(features), 500)
    ]
    rounds = []  # alone and busy, interleaved: a shared machine's noise falls on both
    for _ in range(ROUNDS):
        rounds.append(
            (asyncio.run(_checks(fences, None)), asyncio.run(_checks(fences, _fencing(pages))))
        )
    k = int(np.argsort([np.percentile(a[0], 99) for a, _ in rounds])[len(rounds) // 2])
    (alone, late_alone), _ = rounds[k]  # the median round alone, and busy likewise
    k = int(np.argsort([np.percentile(b[0], 99) for _, b in rounds])[len(rounds) // 2])
    _, (busy, late_busy) = rounds[k]
    _, _, fenced = read_answer("bench", features, rules, BuildOptions(), set())
    t0 = time.perf_counter()
    live = unpack("bench", [p for packed in fenced.values() for p in packed])
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
    """Checks at RATE_HZ for PHASE_S, or while ``work`` (an async function of a stop event
    and a started event) runs until it sets stop: each check's duration and lateness, in
    seconds."""
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
    while not stop.is_set() if work is not None else loop.time() < end:
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


def _fencing(pages, builds=BUILDS):
    """``builds`` answers of new zones fenced one after the other in a spawned, niced worker
    process, as the monitor's (the checks are timed from the first submission to the last
    result)."""

    async def work(stop, started):
        loop = asyncio.get_running_loop()
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=context, initializer=worker_start) as pool:
            await loop.run_in_executor(pool, worker_start)  # the process is up
            started.set()
            rules, options = load_rules(), BuildOptions()
            for _ in range(builds):
                await loop.run_in_executor(pool, read_answer, "bench", pages, rules, options, set())
        stop.set()

    return work


def _swapping(records, frame, swaps=3):
    """The fence set rebuilt ``swaps`` times in a worker thread, as the monitor swaps it."""

    def build():
        fs = FenceSet(records, frame=frame)
        fs.index()

    async def work(stop, started):
        from alphafence.monitor.live_parts import short_switches

        started.set()
        for _ in range(swaps):
            with short_switches():  # as the monitor swaps
                await asyncio.to_thread(build)
        stop.set()

    return work


REFRESH_S = 10.0
SPEED = 5.0


def served_to_onboard(Row) -> list:
    from alphafence.sitl.find import find_sitl_binary

    name = "live zone served -> onboard fence holding it (SITL speedup 1, 5 m/s)"
    target = f"<= {REFRESH_S:.0f} s refresh + 3 s"
    if find_sitl_binary() is None:
        return [Row(name, "skipped: no SITL binary", target, "-", "-", True)]
    import tempfile
    from pathlib import Path

    from tests.live_servers import postgis_missing, pygeoapi_missing, serving

    missing = postgis_missing() or pygeoapi_missing()
    if missing:
        return [Row(name, f"skipped: {missing}", target, "-", "-", True)]
    with tempfile.TemporaryDirectory() as tmp, serving(Path(tmp)) as servers:
        times = asyncio.run(_served(servers))
    worst = max(times)
    return [Row(name, f"max {worst:.1f} s of {len(times)} ({', '.join(f'{t:.1f}' for t in times)})",
                target, "-", "-", worst <= REFRESH_S + 3.0, worst, "s")]  # fmt: skip


async def _served(servers):
    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.live import LiveOptions
    from alphafence.monitor.options import MonitorOptions, RollingOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.sitl import launch_sitl
    from alphafence.sources.ogc import SourceOptions
    from alphafence.vehicle.link import open_vehicle
    from bench.rolling_bench import fly_to
    from tests.live_servers import ed318_zone, insert_zone

    pg, api, table = servers
    start, end = (14.53959, 35.89042), (14.50638, 35.88964)
    base = FenceRecord("anchor", "keep_out", shapely_box(start, 3000.0, 0.0))
    live = LiveOptions(SourceOptions(api.collection), load_rules(), BuildOptions(),
                       refresh_s=REFRESH_S)  # fmt: skip
    rolling = RollingOptions(speed_mps=SPEED)
    async with launch_sitl(home=f"{start[1]},{start[0]},80,270", speedup=1) as sitl:
        async with open_vehicle(sitl.connection_url) as vehicle:
            log = EventLog(None)
            options = MonitorOptions(onboard="rolling", rolling=rolling)
            monitor = Monitor(vehicle, FenceSet([base]), options, log, live=live)
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            await fly_to(vehicle, end, sitl.home.alt + 20.0, SPEED)
            inserted = []
            for k in range(3):
                await asyncio.sleep(7.0)
                here = monitor.engine.last
                ring = shapely_box((here.lon, here.lat), -250.0, 120.0, half=40.0)
                insert_zone(pg, table, ed318_zone(f"BENCH-{k}", list(ring.exterior.coords)))
                inserted.append((f"BENCH-{k}", time.monotonic()))
            deadline = time.monotonic() + 3 * REFRESH_S + 30.0
            while time.monotonic() < deadline and len(_held(log, inserted)) < len(inserted):
                await asyncio.sleep(0.2)
            stop.set()
            await task
    return _held(log, inserted)


def _held(log, inserted) -> list:
    """For each zone inserted, the seconds to the first verified upload after its fences
    were swapped in."""
    out = []
    events = list(log.events)
    for zone, t_insert in inserted:
        seen = [e["time"] for e in events if e["event"] == "source_zone" and e["zone"] == zone]
        if not seen:
            continue
        swapped = [
            e["time"] for e in events if e["event"] == "source_fences" and e["time"] >= seen[0]
        ]
        ups = [e["time"] for e in events if e["event"] in ("onboard_upload", "onboard_kept")
               and swapped and e["time"] >= swapped[0] and e.get("verified", True)]  # fmt: skip
        if ups:
            out.append(ups[0] - t_insert)
    return out


def shapely_box(lonlat, east_m, north_m, half=40.0):
    """A square of ``2 * half`` metres centred ``east_m``, ``north_m`` from ``lonlat``."""
    import shapely

    frame = LocalFrame(*lonlat)
    return frame.geom_to_wgs84(
        shapely.box(east_m - half, north_m - half, east_m + half, north_m + half)
    )


def run(osm, Row) -> list:
    return refresh_cost(Row) + check_p99(osm, Row) + served_to_onboard(Row)


if __name__ == "__main__":
    import sys

    from bench.build_bench import Row

    for r in run(sys.argv[1], Row):
        print(r.name, "|", r.result, "|", r.peer, "|", r.ratio, "|", r.ok)
