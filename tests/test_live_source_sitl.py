"""Zones from a live source in flight (real copter SITL, real PostGIS and pygeoapi on loopback).

The monitor watches the Malta fences (built from the shared extract) and follows a live
source: pygeoapi serving a PostGIS table of ED-318 zones, empty at take-off. SITL starts at
the east end of a 1.6 km leg due west across the Grand Harbour's neighbourhoods (on the rolling
test's line: no keep-out fence within 50 m of it); the copter flies it as an AUTO mission at
5 m/s, speedup 5. The monitor runs with ``--onboard rolling`` (the copter profile),
``--enforce`` and ``--imminent-action reroute``; the source is asked every 6 s (30 s of flight
at speedup 5). The ``copter-rtl`` fence parameters are set once the first rolling fence is in,
so ArduPilot enforces what the monitor uploads.

30 s of flight after take-off a keep-out zone (200 m x 200 m, 900 m along the leg) is inserted
into the table. Asserted: the companion fetched it (``source_zone``), fenced it in its worker
and swapped it in (``source_fences``), uploaded a rolling fence holding it (verified read-back),
re-routed around it (``reroute``, ``reroute_done``), and the copter never came within the
zone's margin (25 m, the rules' geozone margin: distance in a local azimuthal-equidistant frame
centred on the zone, good to millimetres at this size) at any GLOBAL_POSITION_INT; ArduPilot
never reported a breach; the events carry UTC times; the time from the insert to the verified
upload holding the zone is at most one refresh period plus 3 s (and the upload's own time).

Two more flights give the zone a time window: one opening 8 s (wall; 40 s of flight) after the
insert (announced as upcoming, then enforced and flown around), one open at the insert and
closing 8 s later (enforced, then dropped: the rolling fence is compiled again without it and
the copter flies straight through where it was, with no breach).
"""

from __future__ import annotations

import asyncio
import time
from datetime import datetime, timedelta, timezone

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencing.pipeline import BuildOptions
from alphafence.geo.coords import to_e7
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.ids import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT,
    MAV_MISSION_TYPE_MISSION,
)
from alphafence.mavlink.storage import PROFILES
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.live import LiveOptions
from alphafence.monitor.options import RollingOptions
from alphafence.monitor.runner import Monitor
from alphafence.review.replay import speedup_options
from alphafence.sources.ogc import SourceOptions
from alphafence.vehicle.link import open_vehicle
from alphafence.zones.rules import load_rules
from tests.live_servers import ed318_zone, insert_zone
from tests.sitl_flight import (
    ALTITUDE,
    ARM_TIMEOUT,
    FlightLog,
    ask_fence_status,
    retry,
    until,
    unwatch,
    upload_mission,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

START = (14.53959, 35.89042)  # lon, lat: SITL's home, the leg's east end
CLEAR_END = (14.50638, 35.88964)  # 3.0 km west: no keep-out within 50 m of the line
LEG_M = 1600.0
END = tuple(a + (b - a) * LEG_M / 3000.0 for a, b in zip(START, CLEAR_END))  # on that line
SPEEDUP = 5
SPEED = 5.0
REFRESH_S = 30.0 / SPEEDUP  # wall seconds: 30 s of flight
INSERT_AT_M = 150.0  # the zone is inserted once the copter is this far along (30 s of flight)
ZONE_AT_M = 900.0  # the zone's centre, metres west of home along the leg
ZONE_HALF_M = 100.0
MARGIN_M = 25.0  # the default rules' geozone margin
CLEARANCE = 20.0
WINDOW_S = 8.0  # wall seconds from the insert to a window's start or end (40 s of flight)
WALL_TIMEOUT = 300.0


@pytest.fixture(scope="module")
def malta_fences(malta, tmp_path_factory):
    from alphafence.cli import main

    out = tmp_path_factory.mktemp("malta-live") / "fences.geojson"
    assert main(["build", str(malta), "-o", str(out), "-q"]) == 0
    return out


def _events(log, kind):
    return [e for e in log.events if e["event"] == kind]


def _mission(frame, home):
    from alphafence.vehicle.values import RawItem

    relative = MAV_FRAME_GLOBAL_RELATIVE_ALT

    def item(seq, command, lonlat=None, z=ALTITUDE, frame_id=relative, p2=0.0):
        lat = lon = 0
        if lonlat is not None:
            lat, lon = to_e7(lonlat[1]), to_e7(lonlat[0])
        return RawItem(seq, frame_id, command, 1 if seq == 1 else 0, 1, 1.0 if p2 else 0.0,
                       p2, 0.0, 0.0, lat, lon, float(z), MAV_MISSION_TYPE_MISSION)  # fmt: skip

    return [
        item(0, MAV_CMD_NAV_WAYPOINT, START, home.alt, frame_id=MAV_FRAME_GLOBAL),
        item(1, MAV_CMD_NAV_TAKEOFF),
        item(2, MAV_CMD_DO_CHANGE_SPEED, z=0.0, p2=SPEED),  # ground speed for the mission
        item(3, MAV_CMD_NAV_WAYPOINT, END),
        item(4, MAV_CMD_NAV_LAND, END, z=0.0),
    ]


def _window(variant):
    """The zone's ED-318 window: none; opening 8 s (wall) after the insert, 40 s of flight
    before the copter could reach it; or open at the insert and closing 8 s later."""
    now = datetime.now(timezone.utc)
    later = now + timedelta(seconds=WINDOW_S)

    def iso(t):
        return t.isoformat(timespec="seconds").replace("+00:00", "Z")

    if variant == "starts":
        return [{"startDateTime": iso(later), "endDateTime": iso(now + timedelta(hours=1))}]
    if variant == "ends":
        return [{"startDateTime": iso(now - timedelta(hours=1)), "endDateTime": iso(later)}]
    return None


@pytest.mark.parametrize("variant", ["always", "starts", "ends"])
async def test_a_zone_inserted_mid_flight_is_fenced_uploaded_and_flown_around(
    malta_fences, sitl_factory, live_source, variant
):

    pg, api, table = live_source
    frame = LocalFrame(*START)
    fences = FenceSet(read_fences(malta_fences), frame=frame)
    zone_frame = LocalFrame(*frame.to_wgs84(-ZONE_AT_M, 0.0))
    square = shapely.box(-ZONE_HALF_M, -ZONE_HALF_M, ZONE_HALF_M, ZONE_HALF_M)
    ring = list(zone_frame.geom_to_wgs84(square).exterior.coords)
    options, live = monitor_options(api.collection)

    sitl = await sitl_factory(home=f"{START[1]},{START[0]},80,270", speedup=SPEEDUP)
    log = FlightLog(frame)
    results = {}

    async def insert():
        window = _window(variant)
        insert_zone(pg, table, ed318_zone("LIVE-1", ring, "police closure", window))
        results["t_insert"] = time.monotonic()

    async def then():
        await until("the zone", lambda: _events(log, "source_zone"), 4 * REFRESH_S + 30, log)
        if variant == "ends":  # enforced until its end, then dropped
            await until("the window's end", lambda: _windows(log, "ended"), 60, log)
            await until("past the zone",
                        lambda: log.positions[-1][1] < -ZONE_AT_M - 3 * ZONE_HALF_M,
                        120, log)  # fmt: skip
            return False
        if variant == "starts":  # announced first, enforced from its start
            await until("the window's start", lambda: _windows(log, "active"), 60, log)
        return True

    await within(fly_the_leg(sitl, frame, fences, options, live, log, insert, then),
                 WALL_TIMEOUT, log)  # fmt: skip
    events = list(log.events)
    brief = ", ".join(f"{e['event']}@{e['time']:.1f}" for e in events)
    assert not _events(log, "reroute_failed"), brief
    (zone,) = [e for e in events if e["event"] == "source_zone"]
    assert zone["zone"] == "LIVE-1" and zone["change"] == "new" and "keep_out" in zone["kinds"]
    assert zone["window"] == {"always": "always", "starts": "upcoming", "ends": "active"}[variant]
    assert log.fence and all(f["breach_status"] == 0 for _, f in log.fence), log.summary()
    if variant == "ends":  # enforced until its end, then dropped: the copter flies through
        assert not _events(log, "reroute"), brief
        ended = _windows(log, "ended")[0]["time"]
        rolled = [e for e in events if e["event"] in ("onboard_upload", "onboard_kept")
                  and e["reason"] == "windows" and e["time"] > ended]  # fmt: skip
        assert rolled, brief  # the vehicle's fence no longer holds it
        through = min(_distance_to_zone(frame, zone_frame, square, x, y)
                      for _, x, y, _ in log.positions)  # fmt: skip
        assert through == 0.0, through
        return
    swapped = [e for e in events if e["event"] == "source_fences" and e["time"] >= zone["time"]]
    assert swapped and swapped[0]["live"] >= 1, brief
    holding = [
        e for e in events
        if e["event"] == "onboard_upload" and e["time"] >= swapped[0]["time"] and e["verified"]
    ]  # fmt: skip
    assert holding, brief
    # the zone and its margin are inside the exclusions the vehicle holds after that upload
    served_to_onboard = holding[0]["time"] - results["t_insert"]
    print(f"zone served -> onboard fence holding it: {served_to_onboard:.2f} s wall "
          f"(refresh {REFRESH_S:.0f} s)")  # fmt: skip
    assert served_to_onboard <= REFRESH_S + 3.0 + holding[0].get("seconds", 0.0), brief
    for e in events:
        assert e.get("utc", "").endswith("Z"), e
    # never within the zone's margin; ArduPilot never in breach
    nearest = min(
        _distance_to_zone(frame, zone_frame, square, x, y) for _, x, y, _ in log.positions
    )
    print(f"nearest approach to the zone: {nearest:.1f} m (margin {MARGIN_M} m)")
    assert nearest >= MARGIN_M, (nearest, brief)


def monitor_options(collection, clearance=CLEARANCE):
    """The monitor's options for these flights: the rolling onboard fence (copter), enforcing,
    re-routing, and the live source asked every :data:`REFRESH_S`: ``(options, live)``."""
    rolling = RollingOptions(profile=PROFILES["copter"], speed_mps=SPEED, upload_budget_s=15.0)
    options = speedup_options(SPEEDUP, onboard="rolling", rolling=rolling, enforce=True,
                              imminent_action="reroute", reroute_clearance_m=clearance)  # fmt: skip
    live = LiveOptions(SourceOptions(collection), load_rules(), BuildOptions(),
                       refresh_s=REFRESH_S)  # fmt: skip
    return options, live


async def fly_the_leg(sitl, frame, fences, options, live, log, change, then=None):
    """Fly the leg with the monitor following the live source: once the copter is
    :data:`INSERT_AT_M` along, ``await change()`` (a zone inserted, a map updated), then
    ``await then()`` (what to wait for; False: no re-route follows), then the re-route and the
    copter past the zone."""
    from alphafence.vehicle.params import PROFILES as PARAMS
    from alphafence.vehicle.params import apply_params

    monitor_log = EventLog()
    log.events = monitor_log.events
    async with open_vehicle(sitl.connection_url) as vehicle:
        log.texts = vehicle.texts
        watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence", "progress")
        monitor = Monitor(vehicle, fences, options, monitor_log, live=live)
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            await vehicle.telemetry.set_rate_position(10.0)
            await until("the first rolling fence",
                        lambda: _events(log, "onboard_upload") or _events(log, "onboard_kept"),
                        60, log)  # fmt: skip
            await until("the first answer", lambda: _events(log, "source_answer"), 60, log)
            await until("the route planner", lambda: _events(log, "reroute_ready"), 60, log)
            await apply_params(vehicle, PARAMS["copter-rtl"])
            # GUIDED (the re-route's gotos) at the mission's speed too
            await vehicle.param.set_param_float("WPNAV_SPEED", SPEED * 100.0)
            await ask_fence_status(vehicle, 2.0)
            await upload_mission(vehicle, _mission(frame, sitl.home))
            await retry("arming", vehicle.action.arm, ARM_TIMEOUT)
            await vehicle.mission_raw.start_mission()
            await until("AUTO", lambda: log.mode() == "AUTO", 10, log)
            await until("take-off", lambda: log.positions and log.positions[-1][3] > 10, 60, log)
            await until("30 s of flight along the leg",
                        lambda: log.positions[-1][1] < -INSERT_AT_M, 60, log)  # fmt: skip
            await change()
            if then is not None and not await then():
                return
            await until("the re-route",
                        lambda: _events(log, "reroute") or _events(log, "reroute_failed"),
                        120, log, poll=0.01)  # fmt: skip
            await until("reroute_done",
                        lambda: _events(log, "reroute_done") or _events(log, "reroute_failed"),
                        120, log)  # fmt: skip
            await until("past the zone",
                        lambda: log.positions[-1][1] < -ZONE_AT_M - 3 * ZONE_HALF_M, 120, log)  # fmt: skip
            assert not task.done(), "the monitor stopped by itself"
        finally:
            stop.set()
            await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 20)
            await unwatch(watchers)


def _windows(log, state):
    return [e for e in log.events if e["event"] == "source_zone_window" and e["window"] == state]


def _distance_to_zone(frame, zone_frame, square, x, y):
    """Metres from a logged position to the zone, in the zone's own AEQD frame."""
    return float(
        shapely.distance(shapely.Point(zone_frame.to_local(*frame.to_wgs84(x, y))), square)
    )
