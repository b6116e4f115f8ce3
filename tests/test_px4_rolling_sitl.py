"""The rolling onboard fence (``--onboard rolling``) on PX4 (PX4 SITL, SIH quadrotor, real time,
the pymavlink link).

* Along a leg: keep-out squares (40 m) every 200 m beside a 1 km leg due east of home, 60 m off
  it. The monitor runs with ``onboard="rolling"`` and no profile (so PX4's: 64 items) while the
  vehicle flies the leg at 10 m/s. At every position after the first upload the fence in force
  (the last written, and during a re-upload the new one too; each as the monitor downloaded it
  from PX4) contains every keep-out square within reach; every upload is verified, and there
  are several.
* Home: a keep-in area within reach that does not hold home. PX4 would drop it as it loads the
  fence, so the monitor sends nothing (``onboard_upload_failed``, stage ``home``) and PX4 keeps
  the fence it had. Broken case: without the home check the upload goes through, PX4 says
  "Geofence invalid", and the check after the upload (stage ``confirm``) reports it.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import Braking
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor import rolling as rolling_module
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import MonitorOptions, RollingOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.fence_transfer import download_fence
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import apply_params
from tests.test_monitor_rolling_sitl import Layers, exclusions
from tests.test_px4_flight_sitl import HOME, SPEED, Track, _take_off, _watched

pytestmark = [pytest.mark.sitl, pytest.mark.px4]
LEG_EAST = 1000.0
ROLLING = RollingOptions(speed_mps=SPEED)
REACH = ROLLING.reach_m(Braking())
TOLERANCE_M = 0.05


def _squares(frame, centres, kind="keep_out", size=40.0):
    return [
        FenceRecord(f"test/{kind}-{k}", kind, frame.geom_to_wgs84(shapely.box(
            x - size / 2, y - size / 2, x + size / 2, y + size / 2)))
        for k, (x, y) in enumerate(centres)
    ]  # fmt: skip


async def _events(log, *kinds, timeout=60.0):
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not [e for e in log.events if e["event"] in kinds]:
        assert loop.time() < deadline, f"no {kinds} within {timeout:g} s: {log.events}"
        await asyncio.sleep(0.05)
    return [e for e in log.events if e["event"] in kinds]


@pytest.mark.parametrize("link", ["pymavlink"], indirect=True)
async def test_px4s_rolling_fence_holds_every_fence_within_reach_along_a_leg(px4, link):
    frame = LocalFrame(*HOME)
    records = _squares(frame, [(x, 80.0) for x in np.arange(150.0, 1400.0, 200.0)])
    fences = FenceSet(records, frame=frame)
    track = Track(frame)
    log, layers = EventLog(), Layers()
    options = MonitorOptions(onboard="rolling", rolling=ROLLING)
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        await apply_params(vehicle, {"GF_ACTION": 1, "MPC_XY_CRUISE": SPEED})  # PX4 warns only
        monitor = Monitor(vehicle, fences, options, log, observers=[layers])
        layers.monitor = monitor
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))

        async def fly():
            await _events(log, "onboard_upload", "onboard_upload_failed")
            amsl = await _take_off(vehicle, 20.0)
            lon, lat = frame.to_wgs84(np.array([LEG_EAST]), np.array([0.0]))
            await vehicle.action.goto_location(float(lat[0]), float(lon[0]), amsl, float("nan"))
            await track.until("the leg's end", lambda: track.east[-1] > LEG_EAST - 15.0, 150)

        try:
            await _watched(vehicle, track, fly, px4)
        finally:
            stop.set()
            await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 15)
    events = list(log.events)
    uploads = [e for e in events if e["event"] == "onboard_upload"]
    bad = [e for e in events if e["event"] in ("onboard_upload_failed", "onboard_behind")]
    assert not bad, bad
    assert len(uploads) >= 3 and all(u["verified"] is True for u in uploads), uploads
    assert len(layers.loaded) == len(uploads) and all(u["items"] <= 64 for u in uploads)
    timeline = [(u["started"], u["time"], exclusions(layer))
                for u, (_, layer) in zip(uploads, layers.loaded)]  # fmt: skip
    prepared = [shapely.buffer(g, TOLERANCE_M) for _, _, g in timeline]
    times = np.asarray(track.times)
    checked, reached = 0, set()
    for t, x, y in zip(times, track.east, track.north):
        if t < timeline[0][1]:
            continue
        current = max(k for k, (_, done, _) in enumerate(timeline) if done <= t)
        in_force = [current] + ([current + 1] if current + 1 < len(timeline)
                                and timeline[current + 1][0] <= t else [])  # fmt: skip
        for i in fences.tree.query(shapely.Point(x, y), predicate="dwithin", distance=REACH):
            reached.add(records[i].site_id)
            for k in in_force:
                assert shapely.covers(prepared[k], fences.local[i]), (x, y, k, records[i].site_id)
                checked += 1
    print(
        f"\nPX4 rolling fence: {len(uploads)} uploads, items {[u['items'] for u in uploads]}, "
        f"seconds {[u['seconds'] for u in uploads]}; {checked} containment checks, "
        f"{len(reached)} squares reached"
    )
    assert checked > 100 and len(reached) >= 5, (checked, reached)


@pytest.mark.parametrize("link", ["pymavlink"], indirect=True)
@pytest.mark.parametrize("checked", [True, False], ids=["home-checked", "broken-unchecked"])
async def test_px4s_rolling_fence_never_sends_an_area_home_breaches(
    px4, link, checked, monkeypatch
):
    if not checked:

        async def no_check(vehicle, items, timeout=10.0):
            return None

        monkeypatch.setattr(rolling_module, "check_home", no_check)
    frame = LocalFrame(*HOME)
    keep_in = _squares(frame, [(200.0, 0.0)], "keep_in", size=100.0)  # home is outside it
    log = EventLog()
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        before = await download_fence(vehicle)
        options = MonitorOptions(onboard="rolling", rolling=ROLLING)
        monitor = Monitor(vehicle, FenceSet(keep_in, frame=frame), options, log)
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            (failed,) = (await _events(log, "onboard_upload_failed", "onboard_upload"))[:1]
            after = await download_fence(vehicle)
        finally:
            stop.set()
            await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 15)
    assert failed["event"] == "onboard_upload_failed", failed
    if checked:
        assert failed["stage"] == "home" and "nothing was sent" in failed["error"], failed
        assert after == before  # PX4 keeps what it had
    else:  # sent: PX4 stored it and drops the area; the check after the upload says so
        assert failed["stage"] == "confirm" and "PX4 discards" in failed["error"], failed
        assert len(after) == 4 and px4.logged("Geofence invalid")
