"""The empty day: a source of temporary closures that has none in the area. ``build --source``
writes an empty offline copy (``tests/test_hostile_source.py``); a monitor starts from that
copy, or from the source alone, with no fence at all: nothing is in force, and from the
source alone no position is reported CLEAR, until the source's first complete answer; then
its zones are enforced in a frame of their own."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencing.pipeline import BuildOptions
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.live import LiveOptions
from alphafence.monitor.observe import Observer
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.sources.ogc import SourceOptions
from alphafence.zones.rules import load_rules
from tests.helpers import until
from tests.hostile_server import HostileServer
from tests.live_servers import ed318_zone
from tests.test_live_monitor import square
from tests.test_monitor_eventlog import _no_alert, _Telemetry


class Steps(Observer):
    """Every engine step's level, as the live map would show it, and whether it was known."""

    def __init__(self):
        self.steps = []

    def on_step(self, step):
        self.steps.append((step.known, step.level.name))


async def started(server, from_file):
    fences = FenceSet([], frame=LocalFrame(0.0, 0.0))
    live = LiveOptions(SourceOptions(server.collection, retries=0), load_rules(), BuildOptions(),
                       refresh_s=3600.0, from_file=from_file)  # fmt: skip
    log, steps = EventLog(None), Steps()
    vehicle = SimpleNamespace(telemetry=_Telemetry(), system=None)
    monitor = Monitor(vehicle, fences, MonitorOptions(), log, observers=[steps], live=live)
    monitor.feeds.pop("adsb")
    monitor.commands.alert = _no_alert
    return monitor, log, steps


async def test_a_monitor_from_the_source_alone_knows_nothing_until_its_first_answer():
    near = ed318_zone("FIRE", square(14.449, 35.949, 0.002))  # the stub flies at 35.95, 14.45
    with HostileServer([near]) as server:
        server.case = "silent"  # not answering yet: nothing is known
        monitor, log, steps = await started(server, from_file=False)
        monitor.live.options.source = SourceOptions(server.collection, retries=0, timeout_s=1.0)
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            await until(lambda: any(e["event"] == "source_failed" for e in log.events),
                        "the first ask, after the first position, failed")  # fmt: skip
            await until(lambda: len(steps.steps) > 20, "positions checked meanwhile")
            assert all(known is False for known, _ in steps.steps), "reported before an answer"
            assert not monitor.engine.fences.records
            server.case = None
            monitor.live.options.source = SourceOptions(server.collection, retries=0)
            asked = asyncio.ensure_future(monitor.live.next_refresh())
            monitor.live.hint()
            await asked
            (known,) = [e for e in log.events if e["event"] == "source_known"]
            assert known["zones"] == 1
            assert {r.properties["source_zone"] for r in monitor.engine.fences.records} == {"FIRE"}
            assert abs(monitor.engine.fences.frame.lon0 - 14.45) < 0.01  # the zone's own frame
            seen = len(steps.steps)
            await until(lambda: len(steps.steps) > seen + 5, "positions after the answer")
            after = steps.steps[seen + 1 :]
            assert all(k for k, _ in after) and {lvl for _, lvl in after} == {"BREACH"}, after
        finally:
            stop.set()
            await asyncio.wait_for(task, 30)


async def test_a_monitor_from_an_empty_copy_is_known_and_clear():
    with HostileServer([]) as server:
        monitor, log, steps = await started(server, from_file=True)
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            await until(lambda: any(e["event"] == "source_answer" for e in log.events),
                        "the empty source's first answer")  # fmt: skip
            await until(lambda: len(steps.steps) > 5, "positions checked")
            assert set(steps.steps) == {(True, "CLEAR")}
            assert not [e for e in log.events if e["event"] == "source_known"]
        finally:
            stop.set()
            await asyncio.wait_for(task, 30)


def test_the_live_map_never_shows_clear_before_the_first_answer():
    from alphafence.awareness.sample import Sample
    from alphafence.awareness.state import Level
    from alphafence.livemap.view import vehicle_message
    from alphafence.monitor.observe import Step

    s = Sample(1.0, 35.95, 14.45, 20.0)
    options = MonitorOptions()
    assert (
        vehicle_message(Step(s, 1.0, True, Level.CLEAR, (), False), options, 1)["level"]
        == "UNKNOWN"
    )
    assert vehicle_message(Step(s, 1.0, True, Level.CLEAR, ()), options, 1)["level"] == "CLEAR"
