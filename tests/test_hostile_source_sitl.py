"""A monitor on a real copter SITL whose live source turns hostile (``tests/hostile_server.py``
on loopback): a ``Date`` in the year 9999 with a timed zone in the answer, a body nested
200,000 deep, coordinates nested 500 deep, a ``next`` link to the page itself, a zone in force
served with a NaN vertex, every feature malformed. After each, no zone in force has been
lifted and the monitor still runs (its clock's work, every second, included); then a new zone
served is taken within one refresh (the first refresh to start after it was served)."""

from __future__ import annotations

import asyncio
from datetime import datetime, timedelta, timezone

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.live import LiveOptions
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.sources.ogc import SourceOptions
from alphafence.vehicle.link import open_vehicle
from alphafence.zones.rules import load_rules
from tests.hostile_server import HostileServer
from tests.live_servers import ed318_zone
from tests.sitl_flight import FlightLog, until, within

pytestmark = pytest.mark.sitl

HOME = (14.5050, 35.8895)  # lon, lat
REFRESH_S = 2.0
CASES = ("date-9999", "deep-body", "deep-coordinates", "next-self", "nan-vertex", "all-malformed")


def ring(east_m, north_m, half=50.0):
    frame = LocalFrame(*HOME)
    box = shapely.box(east_m - half, north_m - half, east_m + half, north_m + half)
    return list(frame.geom_to_wgs84(box).exterior.coords)


def iso(t):
    return t.isoformat(timespec="seconds").replace("+00:00", "Z")


async def test_a_hostile_source_lifts_nothing_and_the_next_zone_is_taken(sitl_factory):
    now = datetime.now(timezone.utc)
    window = [{"startDateTime": iso(now - timedelta(hours=1)),
               "endDateTime": iso(now + timedelta(hours=6))}]  # fmt: skip
    served = [ed318_zone("A", ring(300, 0)), ed318_zone("B", ring(-300, 0)),
              ed318_zone("W", ring(0, 300), "timed closure", window)]  # fmt: skip
    base = FenceRecord("base/1", "keep_out", shapely.Polygon(ring(0, -600)))
    log = EventLog()
    flight = FlightLog(LocalFrame(*HOME))
    flight.events = log.events
    with HostileServer(served) as server:
        live = LiveOptions(SourceOptions(server.collection, retries=0, limit=2), load_rules(),
                           BuildOptions(), refresh_s=REFRESH_S)  # fmt: skip
        sitl = await sitl_factory(home=f"{HOME[1]},{HOME[0]},20,0")

        def in_force(monitor):
            fs = monitor.engine.fences
            return {r.properties.get("source_zone") for k, r in enumerate(fs.records)
                    if "source_zone" in r.properties and fs.active[k]}  # fmt: skip

        async def refreshes(monitor, n):
            """Wait for ``n`` refreshes to end (the first may have started already)."""
            for _ in range(n):
                await monitor.live.next_refresh()

        async def run():
            async with open_vehicle(sitl.connection_url) as vehicle:
                monitor = Monitor(vehicle, FenceSet([base]), MonitorOptions(), log, live=live)
                stop = asyncio.Event()
                task = asyncio.create_task(monitor.run(stop))
                try:
                    await refreshes(monitor, 1)
                    assert in_force(monitor) == {"A", "B", "W"}, list(log.events)
                    for k, case in enumerate(CASES):
                        server.case = case
                        await refreshes(monitor, 2)  # one at least asked since the case
                        assert in_force(monitor) == {"A", "B", "W"} | {f"N{j}" for j in range(k)}, (
                            case
                        )
                        assert monitor.engine.checks > 0 and not task.done(), case
                        assert monitor.clock_slack_s <= 30.0, case
                        # a new zone, served now: in force after one refresh started since
                        server.case = None
                        server.zones.append(ed318_zone(f"N{k}", ring(-600 + 150 * k, 600)))
                        await refreshes(monitor, 2)
                        assert f"N{k}" in in_force(monitor), (case, list(log.events)[-12:])
                    ticks = monitor.engine.checks
                    await until("positions checked after it all",
                                lambda: monitor.engine.checks > ticks + 10, 60, flight)  # fmt: skip
                    assert not task.done(), "the monitor ended"
                finally:
                    stop.set()
                    await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 30)
                return task

        task = await within(run(), 300.0, flight)
    assert task.exception() is None
    kinds = [e["event"] for e in log.events]
    assert "source_clock" in kinds and "source_zone_kept" in kinds
    refused = [e for e in log.events if e["event"] == "source_clock"]
    assert refused[0].get("refused") and "not applied" in refused[0]["reason"]
    failed = [e["error"] for e in log.events if e["event"] == "source_failed"]
    assert any("nested 200000 deep" in f for f in failed) and any("nested 505" in f for f in failed)
    assert any("none of its" in f for f in failed)
    assert any(
        "the pages loop" in e["error"] for e in log.events if e["event"] == "source_incomplete"
    )
    assert "source_zone_removed" not in kinds
