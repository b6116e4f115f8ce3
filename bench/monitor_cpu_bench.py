"""Issue 12 targets: the monitor's CPU on SITL, per vehicle link, at 10 and 50 Hz telemetry:
under 1 % of an x86 core at 10 Hz and under 2 % at 50 Hz for the link the kit chooses (a Pi
core is about ten times slower: that keeps the Navio2's companion near or under 20 %).

Runs the real monitor (link, telemetry tasks, checker, log writer) against one SITL at speedup
1 over the Malta fences, with position and velocity asked for at each rate, on each link that
is installed (``pymavlink``: the pure-Python link; ``mavsdk``: MAVSDK 4's native binding, the
named peer), and measures this process's CPU time (all its threads, MAVSDK's included) against
wall time and against the positions the monitor checked: the CPU per position. Each figure is
the least of :data:`WINDOWS` windows of :data:`SECONDS` (other work on the machine only ever
adds CPU time: the least is the nearest to the monitor's own).
"""

from __future__ import annotations

import asyncio
import time

from alphafence.sitl.find import find_sitl_binary

SECONDS = 8.0
WINDOWS = 3
SETTLE_S = 3.0  # subscriptions up, the rates applied
RATES = (10.0, 50.0)
TARGETS = {10.0: 0.01, 50.0: 0.02}


async def _measure_one(url, fences, link, hz):
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

    async with open_vehicle(url, link=link) as vehicle:
        checks = Checks()
        monitor = Monitor(
            vehicle, fences, MonitorOptions(), EventLog(None), rate_hz=hz, observers=[checks]
        )
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        await asyncio.sleep(SETTLE_S)
        best = None
        for _ in range(WINDOWS):
            c0, w0, n0 = time.process_time(), time.perf_counter(), checks.n
            await asyncio.sleep(SECONDS)
            cpu, wall, n = time.process_time() - c0, time.perf_counter() - w0, checks.n - n0
            if best is None or cpu / wall < best[0]:
                best = (cpu / wall, n / wall, cpu / max(n, 1))
        stop.set()
        await task
    return best


def malta_fences(osm):
    """The fences built from ``osm`` as the monitor loads them (with names, as a map shows)."""
    from alphafence.build.pipeline import BuildOptions, build_fences
    from alphafence.formats.database import read_database
    from alphafence.formats.fence_geojson import FenceRecord
    from alphafence.formats.rules import load_rules
    from alphafence.monitor.fenceset import FenceSet

    rules = load_rules()
    result = build_fences(read_database([osm], rules).features, rules, BuildOptions())
    return FenceSet(
        [
            FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m, name=f.name, category=f.category)
            for f in result.fences
        ]
    )


async def _measure(osm, links):
    from alphafence.sitl import launch_sitl

    fences = malta_fences(osm)
    out = {}
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        for link in links:
            for hz in RATES:
                out[link, hz] = await _measure_one(sitl.connection_url, fences, link, hz)
    return out, len(fences.records)


def run(osm, Row):
    from alphafence.vehicle.link import LINKS, NoLinkError, choose_link

    if find_sitl_binary() is None:
        return [Row("monitor CPU per link", "skipped: no SITL binary", "-", "-", "-", True)]
    links = []
    for link in LINKS[1:]:
        try:
            links.append(choose_link(link))
        except NoLinkError:
            pass
    chosen = choose_link("auto")
    got, n = asyncio.run(_measure(osm, links))
    rows = []
    for hz in RATES:
        peer = got.get(("mavsdk", hz))
        for link in links:
            share, rate, per = got[link, hz]
            is_peer = link == "mavsdk"
            rows.append(
                Row(
                    f"monitor CPU on SITL, {link} link{' (auto)' if link == chosen else ''}, "
                    f"{hz:g} Hz, {n} Malta fences",
                    f"{100 * share:.2f} % of a core, {1e6 * per:.0f} us/position, "
                    f"{rate:.0f} checks/s",
                    f"< {100 * TARGETS[hz]:g} %" if link == chosen else "-",
                    "-" if is_peer or peer is None else f"mavsdk {100 * peer[0]:.2f} %",
                    "-" if is_peer or peer is None else f"{share / peer[0]:.2f}x",
                    (link != chosen or share < TARGETS[hz]) and rate >= 0.8 * hz,
                    value=100 * share,
                    unit="% of a core",
                    peer_value=None if is_peer or peer is None else 100 * peer[0],
                )
            )
    return rows
