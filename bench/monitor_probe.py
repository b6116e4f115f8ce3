"""The monitor's CPU on a live vehicle link, measured in this process: one implementation for
`make bench` (x86, beside the floor) and for `make navio2-test`'s bench phase (the same code in
the armhf userland under qemu-user, beside x86's).

    python -m bench.monitor_probe --connect udpin:127.0.0.1:14550 --fences fences.geojson \\
        [--hz 10,50] [--link pymavlink] [--floor]

prints one JSON line per rate: ``{"link", "hz", "share", "rate", "per_position_s",
"full_share", "machine", "native"}`` (``full_share``: of the positions, those checked in full) (``share``: of one core; ``native``: which compiled pieces are in use, so that a
missing wheel shows), and with ``--floor`` a line ``{"link": "floor", ...}`` per rate: an
endpoint that does nothing, bound to the same port after the monitor, receiving the datagrams
the vehicle still sends at that rate.

Each figure is the least of :data:`WINDOWS` windows of :data:`SECONDS` (other work on the
machine only ever adds CPU time: the least is the nearest to the monitor's own).
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import json
import platform
import time

SECONDS = 8.0
WINDOWS = 3
SETTLE_S = 3.0  # subscriptions up, the rates applied


def native() -> dict:
    """The compiled pieces the monitor's hot path can use, and whether each is there."""
    out = {}
    for name in ("fastcrc", "numpy", "shapely", "pyproj"):
        out[name] = importlib.util.find_spec(name) is not None
    return out


async def _windows(count):
    """``(share of a core, events/s, CPU s per event)``: the least of the windows."""
    best = None
    for _ in range(WINDOWS):
        c0, w0, n0 = time.process_time(), time.perf_counter(), count()
        await asyncio.sleep(SECONDS)
        cpu, wall, n = time.process_time() - c0, time.perf_counter() - w0, count() - n0
        if best is None or cpu / wall < best[0]:
            best = (cpu / wall, n / wall, cpu / max(n, 1))
    return best


async def measure_monitor(url, fences, link, hz, settle_s=SETTLE_S):
    """The real monitor (link, telemetry, checks, event log) on ``url`` at ``hz``: ``(share of
    a core, positions decided per second, CPU s per position, share of them checked in
    full)``. Nothing observes it (an observer sees every position, which the monitor alone
    does not need to build)."""
    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.vehicle.link import open_vehicle

    async with open_vehicle(url, link=link) as vehicle:
        monitor = Monitor(vehicle, fences, MonitorOptions(), EventLog(None), rate_hz=hz)
        engine = monitor.engine
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        await asyncio.sleep(settle_s)
        checks, full = engine.checks, engine.full_checks
        try:
            share, rate, per = await _windows(lambda: engine.checks)
        finally:
            stop.set()
            await task
        return share, rate, per, (engine.full_checks - full) / max(1, engine.checks - checks)


async def measure_floor(port, settle_s=SETTLE_S):
    """An endpoint doing nothing with the datagrams sent to ``port`` on loopback."""
    n = [0]

    class Count(asyncio.DatagramProtocol):
        def datagram_received(self, data, addr):
            n[0] += 1

    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_datagram_endpoint(Count, local_addr=("127.0.0.1", port))
    try:
        await asyncio.sleep(settle_s)
        return await _windows(lambda: n[0])
    finally:
        transport.close()
        await asyncio.sleep(0.1)  # the socket closed before the next link binds the port


def port_of(url: str) -> int:
    """The port of a ``udpin`` connection (``udpin:HOST:PORT``, ``udpin://HOST:PORT``)."""
    return int(url.rsplit(":", 1)[1])


async def probe(url, fences, link, rates, floor):
    """One JSON-ready dict per measurement."""
    out = []
    for hz in rates:
        share, rate, per, full = await measure_monitor(url, fences, link, hz)
        out.append({"link": link, "hz": hz, "share": share, "rate": rate, "per_position_s": per,
                    "full_share": full})  # fmt: skip
        if floor:
            share, rate, per = await measure_floor(port_of(url))
            out.append({"link": "floor", "hz": hz, "share": share, "rate": rate})
    where = {"machine": platform.machine(), "native": native()}
    return [dict(row, **where) for row in out]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.monitor_probe", description=__doc__)
    p.add_argument("--connect", required=True, help="the vehicle (a udpin URL for --floor)")
    p.add_argument("--fences", required=True, help="fence GeoJSON (alphafence build's)")
    p.add_argument("--hz", default="10,50", help="telemetry rates (default 10,50)")
    p.add_argument("--link", default="pymavlink", help="vehicle link (default pymavlink)")
    p.add_argument("--floor", action="store_true", help="measure the floor after each rate")
    args = p.parse_args(argv)
    from alphafence.awareness.fenceset import FenceSet

    fences = FenceSet.from_geojson(args.fences)
    fences.index()
    rates = [float(v) for v in args.hz.split(",")]
    for row in asyncio.run(probe(args.connect, fences, args.link, rates, args.floor)):
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
