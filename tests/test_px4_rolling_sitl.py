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
* An upload stopped halfway (a plain pymavlink client that stops answering PX4's requests)
  leaves PX4's previous fence whole; the control, the same upload completed, replaces it.
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


async def _first_rolling_upload(px4, fences):
    """Run a rolling monitor on PX4 until its first upload ends (verified or failed): the
    fence PX4 held before, that upload's event, and the fence PX4 holds after it."""
    log = EventLog()
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        before = await download_fence(vehicle)
        options = MonitorOptions(onboard="rolling", rolling=ROLLING)
        monitor = Monitor(vehicle, fences, options, log)
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            (first,) = (await _events(log, "onboard_upload_failed", "onboard_upload"))[:1]
            after = await download_fence(vehicle)
        finally:
            stop.set()
            await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 15)
    return before, first, after


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
    before, failed, after = await _first_rolling_upload(px4, FenceSet(keep_in, frame=frame))
    assert failed["event"] == "onboard_upload_failed", failed
    if checked:
        assert failed["stage"] == "home" and "nothing was sent" in failed["error"], failed
        assert after == before  # PX4 keeps what it had
    else:  # sent: PX4 stored it and drops the area; the check after the upload says so
        assert failed["stage"] == "confirm" and "PX4 discards" in failed["error"], failed
        assert len(after) == 4 and px4.logged("Geofence invalid")


def _raw_upload(c, to, items, stop_at=None):
    """Upload fence ``items`` ((command, vertices, lat e7, lon e7)) with a plain pymavlink link,
    answering PX4's requests; stop answering at item ``stop_at`` until PX4 gives up. Returns
    the MISSION_ACK's result, or None when stopped."""
    from alphafence.mavlink import ids

    fence = ids.MAV_MISSION_TYPE_FENCE
    c.mav.mission_count_send(*to, len(items), fence)
    kinds = ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"]
    while (m := c.recv_match(type=kinds, blocking=True, timeout=10)) is not None:
        if m.get_type() == "MISSION_ACK":
            return m.type
        if m.seq == stop_at:  # PX4 re-asks, then drops the transfer (no ACK to us)
            while c.recv_match(type=kinds, blocking=True, timeout=3) is not None:
                pass
            return None
        cmd, n, lat, lon = items[m.seq]
        c.mav.mission_item_int_send(*to, m.seq, 0, cmd, 0, 1, n, 0, 0, 0, lat, lon, 0, fence)
    raise AssertionError("PX4 stopped answering the upload")


@pytest.mark.parametrize("complete", [False, True], ids=["stopped-halfway", "control-complete"])
async def test_px4_keeps_its_whole_fence_when_an_upload_stops_halfway(px4, complete):
    # the rolling fence's premise on PX4: a failed re-upload leaves the fence in force whole
    # (control: a complete upload does replace it, so the comparison can see a change)
    from pymavlink import mavutil

    from alphafence.geo.coords import to_e7
    from alphafence.mavlink import ids

    frame = LocalFrame(*HOME)

    def polygon(east, n):
        a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        lon, lat = frame.to_wgs84(east + 30.0 * np.cos(a), 30.0 * np.sin(a))
        cmd = ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        return [(cmd, n, to_e7(float(y)), to_e7(float(x))) for x, y in zip(lon, lat)]

    old, new = polygon(200.0, 4) + polygon(400.0, 4), polygon(600.0, 10) + polygon(800.0, 10)

    def run():
        c = mavutil.mavlink_connection(px4.connection_url, source_system=255)
        try:
            px4_beat = f"HEARTBEAT.autopilot=={ids.MAV_AUTOPILOT_PX4}"
            hb = c.recv_match(type="HEARTBEAT", condition=px4_beat, blocking=True, timeout=30)
            to = (hb.get_srcSystem(), hb.get_srcComponent())  # instance N is system N + 1
            assert _raw_upload(c, to, old) == ids.MAV_MISSION_ACCEPTED
            return _raw_upload(c, to, new, None if complete else len(new) // 2 - 3)
        finally:
            c.close()

    result = await asyncio.to_thread(run)
    async with open_vehicle(px4.connection_url, 30, link="pymavlink") as vehicle:
        items = await download_fence(vehicle)
    held = [(i.command, int(i.param1), to_e7(i.lat), to_e7(i.lon)) for i in items]
    if complete:
        assert result == ids.MAV_MISSION_ACCEPTED and held == new
    else:
        assert result is None and held == old, (len(held), held[:2])


@pytest.mark.parametrize("link", ["pymavlink"], indirect=True)
async def test_px4s_rolling_fence_holds_two_keep_in_areas_as_one_inclusion_and_its_gap(px4, link):
    """PX4 intersects its inclusions: the rolling fence of two keep-in areas within reach (home
    in the west one) is one inclusion round them and an exclusion for the gap, which PX4 keeps
    whole and which, by the tests' model of PX4, allows the areas and nothing between them."""
    from tests.test_keep_in_gaps import violations

    frame = LocalFrame(*HOME)
    areas = [FenceRecord(f"test/keep_in-{k}", "keep_in", frame.geom_to_wgs84(shapely.box(*b)))
             for k, b in enumerate([(-150, -150, 150, 150), (250, -150, 450, 150)])]  # fmt: skip
    fences = FenceSet(areas, frame=frame, keep_in_union=True)
    _, done, held = await _first_rolling_upload(px4, fences)
    assert done["event"] == "onboard_upload" and done["verified"], done
    assert "inclusions" not in done  # one inclusion: no union bit to set, none asked
    from tests.ardupilot_model import fence_shapes

    shapes = fence_shapes(held)
    assert sum(c == 5001 for c, _, _ in shapes) == 1 and sum(c == 5002 for c, _, _ in shapes) >= 1
    assert violations(areas, held, "px4", HOME) == 0
    assert not px4.logged("Geofence invalid")
