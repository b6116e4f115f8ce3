"""Issue 4 target: the monitor at 50 Hz telemetry uses under 5 % of one core.

Runs the real monitor (MAVSDK link, telemetry tasks, checker, log writer) against SITL at
speedup 1 with position and velocity streamed at 50 Hz, over Malta-airport fences, and measures
this process's CPU time (all its threads, MAVSDK's included) against wall time.
"""

from __future__ import annotations

import asyncio
import time

from alphafence.sitl.find import find_sitl_binary

SECONDS = 20.0


async def _measure(osm):
    from alphafence.build.pipeline import BuildOptions, build_fences
    from alphafence.formats.database import read_database
    from alphafence.formats.fence_geojson import FenceRecord
    from alphafence.formats.rules import load_rules
    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.fenceset import FenceSet
    from alphafence.monitor.observe import Observer
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.sitl import launch_sitl
    from alphafence.vehicle.link import open_vehicle

    rules = load_rules()
    result = build_fences(read_database([osm], rules).features, rules, BuildOptions())
    fences = FenceSet(
        [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    )
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        async with open_vehicle(sitl.connection_url) as vehicle:

            class Checks(Observer):
                """Counts the positions the monitor checks against the fences."""

                n = 0

                def on_step(self, step):
                    self.n += step.checked

            checks = Checks()
            monitor = Monitor(
                vehicle, fences, MonitorOptions(), EventLog(None), rate_hz=50.0, observers=[checks]
            )
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            await asyncio.sleep(3.0)  # subscriptions up, rates applied
            c0, w0, n0 = time.process_time(), time.perf_counter(), checks.n
            await asyncio.sleep(SECONDS)
            cpu, wall, n = time.process_time() - c0, time.perf_counter() - w0, checks.n - n0
            stop.set()
            await task
    return cpu / wall, n / wall, len(fences.records)


def run(osm, Row):
    if find_sitl_binary() is None:
        return [
            Row(
                "monitor CPU at 50 Hz", "skipped: no SITL binary", "< 5 % of a core", "-", "-", True
            )
        ]
    share, rate, n = asyncio.run(_measure(osm))
    return [
        Row(
            f"monitor on SITL, 50 Hz telemetry, {n} Malta fences, {SECONDS:g} s",
            f"{100 * share:.1f} % of a core",
            "< 5 %",
            f"{rate:.0f} checks/s",
            "-",
            share < 0.05 and rate >= 40,
        )
    ]
