"""ArduPilot's own verdict on the gap construction: two keep-in areas compiled for a vehicle
that reads its inclusions as their intersection (``FENCE_OPTIONS`` 0, as ArduPilot before 4.5
reads them) are one inclusion round them and an exclusion for the gap. With home in either
area the vehicle's FENCE_STATUS reports no breach; with home in the gap it reports one, and
with the gap's exclusion left out (the broken case) it reports none there."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.inclusions import FENCE_OPTIONS
from alphafence.mavlink.items import POLYGON_EXCLUSION
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.clear import KeepClear
from alphafence.onboard.compile import compile_fences
from alphafence.vehicle.fence_transfer import upload_fence
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import apply_params

from .ardupilot_model import polygon_outside
from .sitl_flight import FlightLog, ask_fence_status, until, unwatch, watch
from .test_inclusions_sitl import EGHAM, status_after

pytestmark = pytest.mark.sitl


def layout(frame, shift):
    """Two 400 m keep-in squares 300 m apart, shifted ``shift`` metres east of home."""
    boxes = [(-200 + shift, -200, 200 + shift, 200), (500 + shift, -200, 900 + shift, 200)]
    return [FenceRecord(f"area/{k}", "keep_in", frame.geom_to_wgs84(shapely.box(*b)))
            for k, b in enumerate(boxes)]  # fmt: skip


def compiled(frame, shift, home_clear=True):
    area = frame.geom_to_wgs84(shapely.box(-1500, -500, 1500, 500))
    keep = KeepClear.of((frame.lon0, frame.lat0)) if home_clear else None
    return compile_fences(layout(frame, shift), area, PROFILES["copter"], 2000.0,
                          keep_clear=keep, inclusions="intersection").items  # fmt: skip


def without_home_gap(items, frame):
    """``items`` without the exclusion polygon that holds home (by the tests' model)."""
    k = 0
    while k < len(items):
        n = int(items[k].param1) if items[k].command == POLYGON_EXCLUSION else 1
        run = items[k : k + n]
        if n > 1:
            lat = [it.lat for it in run]
            lon = [it.lon for it in run]
            if not polygon_outside(np.array([frame.lat0]), np.array([frame.lon0]), lat, lon)[0]:
                return items[:k] + items[k + n :]
        k += n
    raise AssertionError("no exclusion holds home")


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_the_vehicle_reads_the_gap_construction_as_the_union(sitl):
    frame = LocalFrame(sitl.home.lon, sitl.home.lat)
    log = FlightLog(frame)
    cases = {
        "home in the west area": (compiled(frame, 0.0), 0),
        "home in the east area": (compiled(frame, -700.0), 0),
        "home in the gap": (compiled(frame, -350.0, home_clear=False), 1),
    }
    gap_fence = cases["home in the gap"][0]
    cases["broken: the gap's exclusion left out"] = (without_home_gap(gap_fence, frame), 0)
    seen = {}
    async with open_vehicle(sitl.connection_url, link="pymavlink") as vehicle:
        tasks = watch(log, vehicle, "fence")
        try:
            params = {"FENCE_ENABLE": 1, "FENCE_TYPE": 4, "FENCE_ACTION": 0, FENCE_OPTIONS: 0}
            for name, (items, _) in cases.items():
                await upload_fence(vehicle, items)
                if not log.fence:  # ArduPilot reports a fence it enforces
                    await apply_params(vehicle, params)
                    await ask_fence_status(vehicle, 2.0)
                    await until("a FENCE_STATUS", lambda: log.fence, 30, log)
                seen[name] = await status_after(vehicle, log, **params)
        finally:
            await unwatch(tasks)
    assert seen == {name: want for name, (_, want) in cases.items()}, seen
