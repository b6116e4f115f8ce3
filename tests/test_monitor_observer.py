"""The monitor's public observer hook: every position the feeds deliver, every engine step and
every event, in the order they happen, on a stub vehicle flying north at the replay test's
keep-out square (tests/test_monitor_replay.py) one position at a time."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from alphafence.awareness.state import Level
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.observe import Observer
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from tests.test_monitor_replay import FRAME, fences

NORTH = range(-100, 265, 5)  # metres north of home along x = 0; the square is 150-250 m north


class Recorder(Observer):
    def __init__(self):
        self.seen = []
        self.velocity = asyncio.Event()
        self.stepped = asyncio.Event()
        self.rtl_done = asyncio.Event()

    def on_value(self, stream, t, value):
        self.seen.append(("value", stream, t, value))
        if stream == "velocity":
            self.velocity.set()

    def on_step(self, step):
        self.seen.append(("step", step))
        self.stepped.set()

    def on_event(self, event):
        self.seen.append(("event", event))
        if event["event"] == "action_done" and event["action"] == "rtl":
            self.rtl_done.set()


class Telemetry:
    """10 m/s north; each position is sent once the previous one has been stepped on (the
    observer says so), so every position gets a step of its own."""

    def __init__(self, recorder):
        self.recorder = recorder
        self.sent = []
        self.done = asyncio.Event()

    async def set_rate_position(self, hz):
        pass

    async def set_rate_velocity_ned(self, hz):
        pass

    async def subscribe_velocity_ned(self):
        yield SimpleNamespace(north_m_s=10.0, east_m_s=0.0, down_m_s=0.0)
        await asyncio.Event().wait()

    async def subscribe_position(self):
        await self.recorder.velocity.wait()
        for y in NORTH:
            lon, lat = (float(v) for v in FRAME.to_wgs84(0.0, float(y)))
            p = SimpleNamespace(
                latitude_deg=lat, longitude_deg=lon, relative_altitude_m=20.0,
                absolute_altitude_m=40.0,
            )  # fmt: skip
            self.recorder.stepped.clear()
            self.sent.append(p)
            yield p
            await self.recorder.stepped.wait()
        self.done.set()
        await asyncio.Event().wait()

    async def _silent(self):
        await asyncio.Event().wait()
        yield None

    subscribe_flight_mode = subscribe_armed = subscribe_gps_info = _silent


class Action:
    def __init__(self):
        self.calls = []

    async def hold(self):
        self.calls.append("hold")

    async def return_to_launch(self):
        self.calls.append("rtl")


async def test_observers_see_every_position_step_and_event_in_order():
    recorder = Recorder()
    telemetry = Telemetry(recorder)
    action = Action()
    vehicle = SimpleNamespace(telemetry=telemetry, action=action, system=None)
    log = EventLog(None)
    monitor = Monitor(vehicle, fences(), MonitorOptions(enforce=True), log, observers=[recorder])
    monitor.feeds.pop("adsb")  # no MAVSDK system behind the stub: no ADS-B
    alerts = []

    async def alert(text, event):
        alerts.append((text, event))

    monitor.commands.alert = alert
    stop = asyncio.Event()
    task = asyncio.create_task(monitor.run(stop))
    await asyncio.wait_for(asyncio.gather(telemetry.done.wait(), recorder.rtl_done.wait()), 30)
    stop.set()
    await asyncio.wait_for(task, 5)

    seen = recorder.seen
    positions = [k for k, s in enumerate(seen) if s[:2] == ("value", "position")]
    steps = [k for k, s in enumerate(seen) if s[0] == "step"]
    assert [seen[k][3] for k in positions] == telemetry.sent and len(steps) == len(NORTH)
    for n, (k, j) in enumerate(zip(positions, steps)):
        step, t = seen[j][1], seen[k][2]
        # each step is on the position that came just before it, at that position's time
        assert k < j and (n + 1 == len(steps) or j < positions[n + 1])
        assert step.sample.t == t and step.sample.lat == telemetry.sent[n].latitude_deg
        assert step.started >= t and step.checked
        # and the events it returned come right after it, in order, as the log has them
        assert [s[1] for s in seen[j + 1 : j + 1 + len(step.events)]] == list(step.events)
    assert [s[1] for s in seen if s[0] == "event"] == list(log.events)
    assert monitor.engine.checks == len(NORTH)
    assert seen[steps[-1]][1].level == monitor.engine.sm.level == Level.BREACH

    levels = [(s[1].level, e) for s in seen if s[0] == "step" for e in s[1].events]
    changes = [(level, e["level"]) for level, e in levels if e["event"] == "level"]
    assert changes == [(Level[name], name) for name in ("WARNING", "IMMINENT", "BREACH")]
    assert [e["action"] for _, e in levels if e["event"] == "action"] == ["brake", "rtl"]
    assert action.calls == ["hold", "rtl"]
    done = [e["action"] for e in log.events if e["event"] == "action_done"]
    assert done == ["brake", "rtl"]  # the runner's own events reach the observers too
    assert [e["level"] for _, e in alerts if e["event"] == "level"] == [
        "WARNING",
        "IMMINENT",
        "BREACH",
    ]
