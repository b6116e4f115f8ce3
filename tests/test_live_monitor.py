"""The monitor's live source against a real pygeoapi over PostGIS, through a proxy that makes
it fail: for each fault, nothing in force is lost and the operator is told; zones are fenced in
the worker process and swapped into the engine's fence set; windows are announced, enforced and
ended. The vehicle side is the SITL test's (``test_live_source_sitl.py``); here the monitor's
own parts run (its engine and event log) without a vehicle."""

from __future__ import annotations

import asyncio
import dataclasses
from datetime import datetime, timedelta, timezone
from types import SimpleNamespace

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions
from alphafence.monitor.engine import Engine
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.live import LiveOptions, LiveSource
from alphafence.sources.ogc import SourceOptions
from tests.fault_proxy import FaultProxy
from tests.live_servers import clear_zones, delete_zone, ed318_zone, insert_zone


def square(lon, lat, d=0.002):
    return [(lon, lat), (lon + d, lat), (lon + d, lat + d), (lon, lat + d), (lon, lat)]


class Companion:
    """The parts of a running monitor a live source uses: its engine, log and handler."""

    def __init__(self, more=()):
        base = FenceRecord("base/1", "keep_out", shapely.box(14.50, 35.90, 14.501, 35.901))
        self.engine = Engine(FenceSet([base, *more]))
        self.log = EventLog()
        self.reroute = SimpleNamespace(mission=None)
        self.clock_slack_s = 0.0

    def handle(self, event):
        self.log.put(event)

    def set_fences(self, fences):
        fences.set_time(datetime.now(timezone.utc), self.clock_slack_s)
        self.engine.set_fences(fences)

    def in_force(self) -> set:
        fs = self.engine.fences
        return {
            r.properties.get("source_zone")
            for k, r in enumerate(fs.records)
            if "source_zone" in r.properties and fs.active[k]
        }

    def events(self, kind) -> list:
        return [e for e in self.log.events if e["event"] == kind]


def iso(dt):
    return dt.isoformat(timespec="seconds").replace("+00:00", "Z")


def window(now, start, end):
    """An ED-318 window from ``now + start`` to ``now + end`` (timedeltas)."""
    return [{"startDateTime": iso(now + start), "endDateTime": iso(now + end)}]


@pytest.fixture
async def setup(shared_source, rules):
    pg, api, table = shared_source
    clear_zones(pg, table)
    insert_zone(pg, table, ed318_zone("A", square(14.51, 35.91)))
    insert_zone(pg, table, ed318_zone("B", square(14.52, 35.91)))
    proxy = await FaultProxy(api.url).start()
    companion = Companion()
    options = LiveOptions(
        SourceOptions(f"{proxy.url}/collections/zones", timeout_s=30.0, retries=0, limit=1),
        rules, BuildOptions(), refresh_s=1.0, stale_after_s=1e-6,
    )  # fmt: skip
    live = LiveSource(companion, options, companion.engine.fences.records)
    async with live.opened():
        await live.refresh()
        assert companion.in_force() == {"A", "B"}, companion.log.events
        yield SimpleNamespace(pg=pg, table=table, proxy=proxy, companion=companion, live=live)
    await proxy.stop()


@pytest.mark.parametrize(
    "fault, said",
    [
        ({"status": 500}, "HTTP 500: server error"),
        ({"delay_s": 3.0}, "no answer within 1 s"),
        ({"truncate": True}, "answer is not JSON"),
        ({"pad_bytes": 40 * 2**20}, "answer larger than 32 MiB"),
        ({"token": "fresh"}, "HTTP 401: the token is missing, expired or wrong"),
        ({"fail_from_page": 2}, "HTTP 503"),
    ],
    ids=["500", "slow", "truncated", "oversized", "expired-token", "page-2-fails"],
)
async def test_a_failing_source_removes_nothing_and_says_so(setup, fault, said):
    s = setup
    delete_zone(s.pg, s.table, "B")  # gone at the source, but unseen
    s.proxy.fault = fault
    source = s.live.options.source
    if "delay_s" in fault:  # a server slower than the timeout
        s.live.options.source = dataclasses.replace(source, timeout_s=1.0)
    await s.live.refresh()
    s.live.options.source = source
    assert s.companion.in_force() == {"A", "B"}
    failed = s.companion.events("source_failed") + s.companion.events("source_incomplete")
    assert failed and said in failed[-1]["error"], s.companion.log.events
    assert s.companion.events("source_stale"), "the ground station is not told"
    s.proxy.fault = {}
    await s.live.refresh()  # a complete answer: B goes now, and it is said
    assert s.companion.in_force() == {"A"}
    assert [e["zone"] for e in s.companion.events("source_zone_removed")] == ["B"]
    assert s.companion.events("source_fresh")


async def test_a_server_stopped_mid_flight_removes_nothing(setup):
    s = setup
    await s.proxy.stop()
    await s.live.refresh()
    assert s.companion.in_force() == {"A", "B"}
    assert "connection refused" in s.companion.events("source_failed")[-1]["error"]


async def test_an_emptied_source_needs_a_second_answer(setup):
    s = setup
    s.proxy.fault = {"empty": True}
    await s.live.refresh()
    assert s.companion.in_force() == {"A", "B"}
    (empty,) = s.companion.events("source_empty")
    assert sorted(empty["kept"]) == ["A", "B"]
    await s.live.refresh()
    assert s.companion.in_force() == set()
    assert sorted(e["zone"] for e in s.companion.events("source_zone_removed")) == ["A", "B"]


async def test_malformed_zones_are_named_and_the_good_ones_apply(setup):
    s = setup
    bad = ed318_zone("BAD", square(14.53, 35.91))
    del bad["properties"]["type"]
    s.proxy.fault = {"extra_features": [bad]}
    insert_zone(s.pg, s.table, ed318_zone("C", square(14.53, 35.92)))
    await s.live.refresh()
    assert s.companion.in_force() == {"A", "B", "C"}
    (named,) = s.companion.events("source_zone_invalid")
    assert "zone BAD: missing zone type" in named["problem"]
    new = [e["zone"] for e in s.companion.events("source_zone") if e["change"] == "new"]
    assert new == ["A", "B", "C"]


async def test_windows_are_announced_enforced_and_ended(setup):
    s = setup
    now = datetime.now(timezone.utc)
    soon = window(now, timedelta(minutes=5), timedelta(hours=1))
    over = window(now, -timedelta(hours=1), -timedelta(minutes=1))
    insert_zone(s.pg, s.table, ed318_zone("SOON", square(14.53, 35.92), window=soon))
    insert_zone(s.pg, s.table, ed318_zone("OVER", square(14.54, 35.92), window=over))
    await s.live.refresh()
    windows = {e["zone"]: e["window"] for e in s.companion.events("source_zone")}
    assert windows["SOON"] == "upcoming" and windows["OVER"] == "ended", windows
    assert s.companion.in_force() == {"A", "B"}  # neither is enforced now
    s.live.tick(now + timedelta(minutes=6))  # the window opens
    (opened,) = s.companion.events("source_zone_window")
    assert opened["zone"] == "SOON" and opened["window"] == "active"
    s.companion.engine.fences.set_time(now + timedelta(minutes=6))
    assert s.companion.in_force() == {"A", "B", "SOON"}


async def test_a_clock_ten_minutes_off_widens_the_windows(setup):
    s = setup
    now = datetime.now(timezone.utc)
    soon = window(now, timedelta(minutes=5), timedelta(hours=1))
    insert_zone(s.pg, s.table, ed318_zone("SOON", square(14.53, 35.92), window=soon))
    s.proxy.fault = {"date_offset_s": 600.0}  # the source's clock (or ours) is 10 minutes off
    await s.live.refresh()
    (clock,) = s.companion.events("source_clock")
    assert 590 < clock["skew_s"] < 610
    assert s.companion.in_force() == {"A", "B", "SOON"}  # enforced: it may have started


async def test_the_fences_are_built_in_the_worker_and_swapped_in(setup):
    s = setup
    swapped = s.companion.events("source_fences")
    assert swapped and swapped[-1]["live"] == 4  # A and B: a keep-out and a warning each
    version = s.companion.engine.fences
    await s.live.refresh()  # nothing changed: nothing rebuilt
    assert s.companion.engine.fences is version
    loop = asyncio.get_running_loop()
    worker = await loop.run_in_executor(s.live.pool, _pid)
    assert worker != _pid()  # a process of its own
    assert await loop.run_in_executor(s.live.pool, _niceness) >= 10


def _pid():
    import os

    return os.getpid()


def _niceness():
    import os

    return os.nice(0)
