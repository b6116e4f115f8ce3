"""A prison added on the map reaches a flying vehicle's fence (real copter SITL, real PostGIS
and pygeoapi on loopback): ``alphafence update`` -> PostGIS -> pygeoapi -> ``--source``.

The fleet's fences are the Malta extract's, built with ``--store`` into a PostGIS table that
pygeoapi serves. The monitor watches the same fences from a file and follows the served table
(``--onboard rolling``, ``--enforce``, ``--imminent-action reroute``; asked every 6 s, 30 s
of flight at speedup 5). The copter flies the live-source test's 1.6 km leg west across the
Grand Harbour's neighbourhoods. 30 s of flight after take-off, a change file adding a prison
(a closed way tagged ``amenity=prison``, 200 m x 200 m, 900 m along the leg) is applied with
``alphafence update``. Asserted: the update replaced only that site's rows, at the table's
next version; the companion fetched its fences (``source_zone``), swapped them in, uploaded a
rolling fence holding them (verified read-back) and re-routed; the copter never came within
the prison's margin (50 m) and ArduPilot never reported a breach.
"""

from __future__ import annotations

import asyncio
import time

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencing.pipeline import BuildOptions
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.storage import PROFILES
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.live import LiveOptions
from alphafence.monitor.options import RollingOptions
from alphafence.monitor.runner import Monitor
from alphafence.review.replay import speedup_options
from alphafence.sources.ogc import SourceOptions
from alphafence.vehicle.link import open_vehicle
from alphafence.zones.rules import load_rules
from tests.live_servers import (
    PostGIS,
    Pygeoapi,
    postgis_missing,
    postgres_provider,
    pygeoapi_missing,
)
from tests.sitl_flight import (
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
from tests.test_live_source_sitl import (
    INSERT_AT_M,
    REFRESH_S,
    SPEED,
    SPEEDUP,
    START,
    WALL_TIMEOUT,
    ZONE_AT_M,
    ZONE_HALF_M,
    _distance_to_zone,
    _events,
    _mission,
)

pytestmark = pytest.mark.sitl

PRISON_MARGIN_M = 50.0  # the default rules' prison margin
CLEARANCE = 20.0
FIRST_ID = 9_000_000_000  # beyond the extract's node and way ids


@pytest.fixture
def fleet(malta, tmp_path):
    """The Malta fences built with a store into a PostGIS table, served by pygeoapi."""
    from alphafence.cli import main

    for missing in (pygeoapi_missing(), postgis_missing()):
        if missing:
            pytest.skip(missing)
    pg = PostGIS(tmp_path / "pg").start()
    api = None
    try:
        table = f"{pg.url}/public.zones"
        store = tmp_path / "store.sqlite"
        assert main(["build", str(malta), "-o", table, "--store", str(store), "-q"]) == 0
        local = tmp_path / "fences.geojson"
        assert main(["build", str(malta), "-o", str(local), "-q"]) == 0
        api = Pygeoapi(tmp_path / "api", postgres_provider(pg, "zones")).start()
        yield pg, api, store, local
    finally:
        if api is not None:
            api.stop()
        pg.stop()


def _prison_change(path, ring):
    """A change file creating a prison: four new nodes and the closed way through them."""
    import osmium
    from osmium.osm import mutable

    ids = list(range(FIRST_ID, FIRST_ID + 4))
    with osmium.SimpleWriter(str(path)) as w:
        for n, (lon, lat) in zip(ids, ring[:4]):
            w.add_node(mutable.Node(id=n, location=(lon, lat), version=1))
        w.add_way(mutable.Way(id=FIRST_ID, nodes=[*ids, ids[0]], version=1,
                              tags={"amenity": "prison", "name": "New prison"}))  # fmt: skip
    return f"prison/way/{FIRST_ID}"


async def test_a_prison_added_on_the_map_reaches_the_flying_vehicle(fleet, sitl_factory, tmp_path):
    from alphafence.cli import main
    from alphafence.vehicle.params import PROFILES as PARAMS
    from alphafence.vehicle.params import apply_params

    pg, api, store, local = fleet
    frame = LocalFrame(*START)
    fences = FenceSet(read_fences(local), frame=frame)
    zone_frame = LocalFrame(*frame.to_wgs84(-ZONE_AT_M, 0.0))
    square = shapely.box(-ZONE_HALF_M, -ZONE_HALF_M, ZONE_HALF_M, ZONE_HALF_M)
    ring = list(zone_frame.geom_to_wgs84(square).exterior.coords)
    site = _prison_change(tmp_path / "prison.osc", ring)
    version_before = pg.sql("SELECT max(version) FROM zones")[0][0]
    rows_before = pg.sql("SELECT id, version FROM zones ORDER BY id")
    rolling = RollingOptions(profile=PROFILES["copter"], speed_mps=SPEED, upload_budget_s=15.0)
    options = speedup_options(SPEEDUP, onboard="rolling", rolling=rolling, enforce=True,
                              imminent_action="reroute", reroute_clearance_m=CLEARANCE)  # fmt: skip
    live = LiveOptions(SourceOptions(api.collection), load_rules(), BuildOptions(),
                       refresh_s=REFRESH_S)  # fmt: skip

    sitl = await sitl_factory(home=f"{START[1]},{START[0]},80,270", speedup=SPEEDUP)
    log = FlightLog(frame)
    monitor_log = EventLog()
    log.events = monitor_log.events
    results = {}

    async def flight():
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
                await vehicle.param.set_param_float("WPNAV_SPEED", SPEED * 100.0)
                await ask_fence_status(vehicle, 2.0)
                await upload_mission(vehicle, _mission(frame, sitl.home))
                await retry("arming", vehicle.action.arm, ARM_TIMEOUT)
                await vehicle.mission_raw.start_mission()
                await until("AUTO", lambda: log.mode() == "AUTO", 10, log)
                await until(
                    "take-off", lambda: log.positions and log.positions[-1][3] > 10, 60, log
                )
                await until("30 s of flight along the leg",
                            lambda: log.positions[-1][1] < -INSERT_AT_M, 60, log)  # fmt: skip
                results["t_update"] = time.monotonic()
                argv = ["update", str(tmp_path / "prison.osc"), "--store", str(store), "-q"]
                results["status"] = await asyncio.to_thread(main, argv)
                results["t_written"] = time.monotonic()
                await until("the prison's fences",
                            lambda: [e for e in _events(log, "source_zone")
                                     if str(e["zone"]).startswith(site)],
                            4 * REFRESH_S + 30, log)  # fmt: skip
                await until("the re-route",
                            lambda: _events(log, "reroute") or _events(log, "reroute_failed"),
                            120, log, poll=0.01)  # fmt: skip
                await until("reroute_done",
                            lambda: _events(log, "reroute_done") or _events(log, "reroute_failed"),
                            120, log)  # fmt: skip
                await until("past the prison",
                            lambda: log.positions[-1][1] < -ZONE_AT_M - 3 * ZONE_HALF_M, 120, log)  # fmt: skip
                assert not task.done(), "the monitor stopped by itself"
            finally:
                stop.set()
                await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 20)
                await unwatch(watchers)

    await within(flight(), WALL_TIMEOUT, log)
    events = list(log.events)
    brief = ", ".join(f"{e['event']}@{e['time']:.1f}" for e in events)
    assert results["status"] == 0
    # the update: the prison's rows at the next version, every other row as it was
    after = pg.sql("SELECT id, version FROM zones ORDER BY id")
    new = [(i, v) for i, v in after if i.startswith(site + "#")]
    assert sorted(i for i, _ in new) == [f"{site}#keep_out#0", f"{site}#warning#0"]
    assert {v for _, v in new} == {version_before + 1}
    assert [r for r in after if not r[0].startswith(site + "#")] == rows_before
    assert not _events(log, "reroute_failed"), brief
    zones = [e for e in events if e["event"] == "source_zone" and str(e["zone"]).startswith(site)]
    assert zones and all(z["change"] == "new" for z in zones), brief
    swapped = [e for e in events if e["event"] == "source_fences" and e["time"] >= zones[0]["time"]]
    assert swapped, brief
    holding = [e for e in events if e["event"] == "onboard_upload"
               and e["time"] >= swapped[0]["time"] and e["verified"]]  # fmt: skip
    assert holding, brief
    print(f"map change -> vehicle's fence holding it: "
          f"{holding[0]['time'] - results['t_update']:.2f} s wall (update "
          f"{results['t_written'] - results['t_update']:.2f} s, refresh {REFRESH_S:.0f} s, "
          f"upload {holding[0].get('seconds', 0.0):.2f} s)")  # fmt: skip
    # written, then served at the companion's next ask, then fenced and uploaded
    to_onboard = holding[0]["time"] - results["t_written"]
    assert to_onboard <= REFRESH_S + 3.0 + holding[0].get("seconds", 0.0), brief
    assert log.fence and all(f["breach_status"] == 0 for _, f in log.fence), log.summary()
    nearest = min(
        _distance_to_zone(frame, zone_frame, square, x, y) for _, x, y, _ in log.positions
    )
    print(f"nearest approach to the prison: {nearest:.1f} m (margin {PRISON_MARGIN_M} m)")
    assert nearest >= PRISON_MARGIN_M, (nearest, brief)
