"""The runner downloads the vehicle's fence when it starts (and whenever told to: after an
upload of its own) and hands it to the engine as the onboard layer; a vehicle with no fence,
a hostile fence or a failed download is an event and an alert, and the monitor goes on with
the full-resolution fences. Against the scripted ArduPilot peer (tests/fake_vehicle.py)
through MAVSDK, as the monitor meets a real vehicle."""

from __future__ import annotations

import asyncio

import pytest

from alphafence.monitor.engine import Sample
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.observe import Observer
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from tests.fake_vehicle import FakeVehicle, Faults
from tests.test_monitor_onboard import (
    CIRCLE_EDGE,
    CIRCLE_R,
    FRAME,
    SPEED,
    circle_item,
    full_fences,
    return_point,
    square_items,
)

ONBOARD_EVENTS = ("onboard_fence", "onboard_none", "onboard_failed")


class Waiter(Observer):
    """Sets ``arrived`` when an onboard event is logged."""

    def __init__(self):
        self.arrived = asyncio.Event()

    def on_event(self, event):
        if event["event"] in ONBOARD_EVENTS:
            self.arrived.set()


async def run_monitor_on(fake, options=None, body=None):
    """A monitor on a MAVSDK connection to ``fake`` until its first onboard event (or, with
    the layer off, for a moment), then ``body(monitor)``; returns (monitor, events, alerts)."""
    alerts = []
    async with open_vehicle(fake.url, 10) as vehicle:
        waiter = Waiter()
        log = EventLog(None)
        monitor = Monitor(
            vehicle, full_fences(), options or MonitorOptions(), log, observers=[waiter]
        )

        async def alert(text, event):
            alerts.append(text)

        monitor.commands.alert = alert
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            if monitor.engine.options.onboard == "watch":
                await asyncio.wait_for(waiter.arrived.wait(), 30)
            else:  # the feeds' tasks exist (the download's would be created with them)
                await asyncio.wait_for(started(monitor), 30)
            if body is not None:
                await body(monitor)
            assert not task.done(), "the monitor stopped by itself"
        finally:
            stop.set()
            await asyncio.wait_for(task, 10)
    return monitor, list(log.events), alerts


async def started(monitor):
    while not monitor.tasks:
        await asyncio.sleep(0.01)


def step_north(engine, y):
    lon, lat = FRAME.to_wgs84(0.0, y)
    s = Sample(engine.checks * 0.1, float(lat), float(lon), 20.0, vn=SPEED, armed=True)
    return engine.step(s)


async def test_the_vehicles_fence_is_loaded_at_start_and_checked():
    fence = [return_point(), circle_item(0, 350, CIRCLE_R), *square_items()]
    async with FakeVehicle(fence=fence) as fake:
        monitor, events, alerts = await run_monitor_on(fake)
        assert fake.received("MISSION_REQUEST_LIST"), "no fence download"
    (loaded,) = [e for e in events if e["event"] in ONBOARD_EVENTS]
    assert loaded["event"] == "onboard_fence" and loaded["cause"] == "start"
    assert loaded["items"] == 6 and loaded["seconds"] > 0
    assert loaded["fences"] == {"exclusion circle": 1, "exclusion polygon": 1}
    layer = monitor.engine.onboard
    assert [f.name for f in layer.fences] == [
        "onboard exclusion circle 1 (item 1)",
        "onboard exclusion polygon 1 (items 2-5)",
    ]
    assert alerts == []  # a fence loaded is nothing to alert the ground station about
    # the engine now checks the vehicle's circle: IMMINENT where the real square is far
    engine = monitor.engine
    found = []
    for y in range(0, int(CIRCLE_EDGE)):
        found += [e for e in step_north(engine, float(y)) if e.get("level") == "IMMINENT"]
    assert found and found[0]["fence"] == "onboard exclusion circle 1 (item 1)"
    assert found[0]["onboard_only"] is True


async def test_a_reload_after_an_upload_replaces_the_layer():
    async with FakeVehicle(fence=[circle_item(0, 350, CIRCLE_R)]) as fake:

        async def body(monitor):
            first = monitor.engine.onboard
            fake.fence = [type(fake.fence[0]).of(i) for i in square_items()]  # as if uploaded
            events = await monitor.reload_onboard()
            assert events[0]["event"] == "onboard_fence" and events[0]["cause"] == "upload"
            assert monitor.engine.onboard is not first
            assert monitor.engine.onboard.counts == {"exclusion polygon": 1}

        _, events, _ = await run_monitor_on(fake, body=body)
    assert [e.get("cause") for e in events if e["event"] in ONBOARD_EVENTS] == ["start", "upload"]


@pytest.mark.parametrize(
    "faults, says",
    [
        (Faults(item_fields={0: {"command": 16}}), "item 0: command 16 is not a fence item"),
        (Faults(item_fields={2: {"param1": 0.0}}), "item 2: polygon vertex count 0"),
    ],
)
async def test_a_failed_download_is_an_event_and_the_monitor_goes_on(faults, says):
    async with FakeVehicle(fence=square_items(), faults=faults) as fake:
        monitor, events, alerts = await run_monitor_on(fake)
    (failed,) = [e for e in events if e["event"] in ONBOARD_EVENTS]
    assert failed["event"] == "onboard_failed" and says in failed["error"]
    assert failed["kept"] == "no onboard fence: the full-resolution fences only"
    assert monitor.engine.onboard is None and alerts == ["AF onboard fence unreadable"]
    # the full-resolution fences are still checked
    found = []
    for y in range(200, 300):
        found += [e for e in step_north(monitor.engine, float(y)) if e.get("level") == "IMMINENT"]
    assert found and found[0]["fence"] == "hospital/way/7"


async def test_a_vehicle_without_a_fence_is_an_event():
    async with FakeVehicle(fence=()) as fake:
        monitor, events, alerts = await run_monitor_on(fake)
    (none,) = [e for e in events if e["event"] in ONBOARD_EVENTS]
    assert none["event"] == "onboard_none" and none["items"] == 0
    assert none["reason"] == "the vehicle holds no fence"
    assert monitor.engine.onboard is None and alerts == ["AF no onboard fence"]


async def test_a_stub_vehicle_without_fence_transfers_is_an_event_too():
    # anything the download raises (here: no mission_raw plugin at all) is an event
    from types import SimpleNamespace

    monitor = Monitor(SimpleNamespace(), full_fences(), MonitorOptions(), EventLog(None))
    events = await monitor.reload_onboard("start")
    assert events[0]["event"] == "onboard_failed" and "AttributeError" in events[0]["error"]


async def test_with_the_layer_off_nothing_is_downloaded():
    async with FakeVehicle(fence=square_items()) as fake:
        monitor, events, _ = await run_monitor_on(fake, MonitorOptions(onboard="off"))
        assert "onboard:start" not in [t.get_name() for t in monitor.tasks]
        assert not fake.received("MISSION_REQUEST_LIST")
    assert monitor.engine.onboard is None
    assert not [e for e in events if e["event"] in ONBOARD_EVENTS]


async def test_the_position_check_is_indexed_before_the_first_position():
    """The check's grid (seconds at 100,000 fences) is built as the monitor starts, never on
    the event loop at the vehicle's first position: the scripted vehicle sends none."""
    async with FakeVehicle(fence=()) as fake:
        monitor, events, alerts = await run_monitor_on(fake)
    assert monitor.engine.checks == 0
    assert monitor.engine.fences._grid is not None
