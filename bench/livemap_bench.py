"""The live map's cost to the monitor: the monitor's CPU on SITL with the map served and a page
connected, against the same monitor without the map, at 10 and 50 Hz telemetry.

Runs the real monitor (the link the kit chooses, telemetry tasks, checker) against one SITL at
speedup 1 over the Malta fences, as ``monitor_cpu_bench`` does, three ways: without the map;
with the map served (``LiveMap`` observing, aiohttp on the monitor's loop) and no page; and
with one page connected: a WebSocket client in a process of its own, reading every message
(so its CPU is not counted). The figure is this process's CPU time (all its threads) against
wall time, the least of :data:`WINDOWS` windows of :data:`SECONDS`; the page's messages are
counted to show it was fed. Target: no check lost to the map (checks/s within 10 % of the
rate, each way); the ratio to the monitor without the map is reported (no target: at 10 Hz
the monitor alone is a fraction of a percent of a core).
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time

from alphafence.sitl.find import find_sitl_binary

SECONDS = 6.0
WINDOWS = 2
SETTLE_S = 3.0
RATES = (10.0, 50.0)
WAYS = ("no map", "map, no page", "map + 1 page")

# a page: counts messages and, for each vehicle message, how long after its position reached
# the monitor it arrived (CLOCK_MONOTONIC is one clock for every process on Linux)
PAGE = """
import asyncio, json, sys, time, aiohttp
async def main():
    n, late = 0, []
    async with aiohttp.ClientSession() as s:
        async with s.ws_connect(sys.argv[1]) as ws:
            print("open", flush=True)
            async for m in ws:
                n += 1
                msg = json.loads(m.data)
                if msg.get("type") == "vehicle":
                    late.append(time.monotonic() - msg["t"])
                if n % 50 == 0 and late:
                    late.sort()
                    p99 = late[min(len(late) - 1, int(0.99 * len(late)))]
                    print(n, round(1000 * late[len(late) // 2], 1), round(1000 * p99, 1),
                          flush=True)
asyncio.run(main())
"""


async def _measure_one(url, fences, hz, way):
    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.observe import Observer
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.vehicle.link import open_vehicle

    class Checks(Observer):
        """Counts the positions the monitor checks against the fences."""

        n = 0

        def on_step(self, step):
            self.n += step.checked

    checks = Checks()
    observers, server, page = [checks], None, None
    if way != "no map":
        from alphafence.livemap.observer import LiveMap
        from alphafence.livemap.server import start_map_server

        livemap = LiveMap(fences)
        observers.append(livemap)
        server = await start_map_server(livemap, "127.0.0.1", 0)
    async with open_vehicle(url) as vehicle:
        monitor = Monitor(
            vehicle, fences, MonitorOptions(), EventLog(None), rate_hz=hz, observers=observers
        )
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        if way == "map + 1 page":
            page = subprocess.Popen(
                [sys.executable, "-c", PAGE, f"ws://127.0.0.1:{server.port}/ws"],
                stdout=subprocess.PIPE,
                text=True,
            )
            await asyncio.to_thread(page.stdout.readline)  # open
        await asyncio.sleep(SETTLE_S)
        best = None
        for _ in range(WINDOWS):
            c0, w0, n0 = time.process_time(), time.perf_counter(), checks.n
            await asyncio.sleep(SECONDS)
            cpu, wall, n = time.process_time() - c0, time.perf_counter() - w0, checks.n - n0
            if best is None or cpu / wall < best[0]:
                best = (cpu / wall, n / wall)
        stop.set()
        await task
    received, latency = 0, None
    if page is not None:
        page.terminate()
        lines = page.communicate(timeout=10)[0].split("\n")
        last = [line.split() for line in lines if len(line.split()) == 3]
        if last:
            received, latency = int(last[-1][0]), (float(last[-1][1]), float(last[-1][2]))
    if server is not None:
        await server.close()
    return (*best, received, latency)


async def _measure(osm):
    from alphafence.sitl import launch_sitl
    from bench.monitor_cpu_bench import malta_fences

    fences = malta_fences(osm)
    out = {}
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        for hz in RATES:
            for way in WAYS:
                out[hz, way] = await _measure_one(sitl.connection_url, fences, hz, way)
    return out, len(fences.records)


def run(osm, Row):
    """The rows: the monitor's CPU each way at each rate, the page's against none."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        return [Row("live map CPU", "skipped: no aiohttp (the map extra)", "-", "-", "-", True)]
    if find_sitl_binary() is None:
        return [Row("live map CPU", "skipped: no SITL binary", "-", "-", "-", True)]
    got, n = asyncio.run(_measure(osm))
    rows = []
    for hz in RATES:
        base = got[hz, "no map"][0]
        for way in WAYS:
            share, rate, received, latency = got[hz, way]
            ratio = share / base if base > 0 else float("inf")
            fed = f", page got {received} messages" if way == "map + 1 page" else ""
            rows.append(
                Row(
                    f"monitor CPU on SITL, {hz:g} Hz, {n} Malta fences: {way}",
                    f"{100 * share:.2f} % of a core, {rate:.0f} checks/s{fed}",
                    f">= {0.9 * hz:g} checks/s",
                    "-" if way == "no map" else f"no map {100 * base:.2f} %",
                    "-" if way == "no map" else f"{ratio:.2f}x",
                    rate >= 0.9 * hz,
                )
            )
        share, rate, received, latency = got[hz, "map + 1 page"]
        if latency is not None:
            p50, p99 = latency
            rows.append(
                Row(
                    f"live map: a position on the page after it reached the monitor, {hz:g} Hz",
                    f"p50 {p50:.0f} ms, p99 {p99:.0f} ms (positions sent at most 20 a second)",
                    "p99 <= 200 ms",
                    "-",
                    "-",
                    p99 <= 200.0,
                )
            )
    return rows
