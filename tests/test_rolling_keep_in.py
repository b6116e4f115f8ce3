"""The rolling onboard fence with two keep-in areas, on firmware of each rule: ArduPilot 4.5
and later holds them as two inclusions and gets FENCE_OPTIONS' union bit set and read back;
older firmware holds one inclusion round them and an exclusion for the gap, and no bit is
set. Either way the vehicle, by the tests' model of ArduPilot, is allowed in the areas only,
and home (and the vehicle) are left clear."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from tests.fake_vehicle import FakeVehicle

from . import ardupilot_model
from .helpers import until
from .test_keep_in_gaps import violations
from .test_monitor_rolling import FRAME, sample_at

# two 400 m keep-in squares 100 m apart (both within the rolling radius), home in the west one
AREAS = [
    FenceRecord(f"area/{k}", "keep_in", FRAME.geom_to_wgs84(shapely.box(*b)))
    for k, b in enumerate([(-200, -200, 200, 200), (300, -200, 700, 200)])
]
HOME = tuple(float(v) for v in FRAME.to_wgs84(0.0, 0.0))
PARAMS = {"FENCE_ENABLE": 1, "FENCE_TYPE": 7, "FENCE_ACTION": 1, "FENCE_OPTIONS": 1}


def inclusion_count(items):
    return len([s for s in ardupilot_model.fence_shapes(items) if s[0] in (5001, 5003)])


async def rolled(firmware, params=PARAMS):
    """One rolling upload with the vehicle at home; the fake after it and the events."""
    async with FakeVehicle(params=dict(params), firmware=firmware, home=HOME) as fake:
        async with open_vehicle(fake.url, 10) as vehicle:
            log = EventLog(None)
            monitor = Monitor(vehicle, FenceSet(AREAS, FRAME, keep_in_union=True),
                              MonitorOptions(onboard="rolling"), log)  # fmt: skip
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            try:
                await until(lambda: monitor.tasks, "run() started")
                assert await asyncio.wait_for(monitor.rolling.consider(sample_at(0, 0)), 60)
            finally:
                stop.set()
                await asyncio.wait_for(task, 10)
        return fake, list(log.events)


@pytest.mark.parametrize("firmware", [(4, 5, 0), (4, 7, 0)])
def test_firmware_that_reads_the_union_bit_gets_it_set(firmware):
    fake, events = asyncio.run(rolled(firmware))
    (up,) = [e for e in events if e["event"] == "onboard_upload"]
    assert up["inclusions"] == "union" and fake.params["FENCE_OPTIONS"] == 3
    assert inclusion_count(fake.fence) == 2
    lon, lat = FRAME.to_wgs84(np.array([0.0, 500.0, 250.0]), np.array([0.0, 0.0, 0.0]))
    # read as the union the bit makes: both areas allowed, the gap not
    assert list(ardupilot_model.breached(fake.fence, lon, lat, union=True)) == [False, False, True]


@pytest.mark.parametrize("firmware, params", [((4, 4, 0), PARAMS),
                                              ((4, 7, 0), {"FENCE_ENABLE": 1})])  # fmt: skip
def test_firmware_that_intersects_gets_one_inclusion_and_its_gap(firmware, params):
    fake, events = asyncio.run(rolled(firmware, params))
    (up,) = [e for e in events if e["event"] == "onboard_upload"]
    assert up["items"] == len(fake.fence) and inclusion_count(fake.fence) == 1
    assert not fake.received("PARAM_SET") and fake.params.get("FENCE_OPTIONS", 1) == 1
    assert violations(AREAS, fake.fence, "ardupilot", HOME) == 0
    lon, lat = FRAME.to_wgs84(np.array([0.0, 500.0, 250.0]), np.array([0.0, 0.0, 0.0]))
    assert list(ardupilot_model.breached(fake.fence, lon, lat)) == [False, False, True]


def test_broken_a_rolling_fence_that_never_sets_the_bit_is_caught(monkeypatch):
    from alphafence.monitor import rolling

    async def no_bit(self, items):
        return "union"

    monkeypatch.setattr(rolling.RollingFence, "_union", no_bit)
    fake, _ = asyncio.run(rolled((4, 7, 0)))
    lon, lat = FRAME.to_wgs84(np.array([500.0]), np.array([0.0]))
    # the vehicle's own reading (bit 1 unset: the intersection) forbids the east area
    assert fake.params["FENCE_OPTIONS"] == 1
    assert ardupilot_model.breached(fake.fence, lon, lat, union=False)[0]
