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
from alphafence.geo.frame import LocalFrame
from tests.live_servers import (
    PostGIS,
    Pygeoapi,
    postgis_missing,
    postgres_provider,
    pygeoapi_missing,
)
from tests.sitl_flight import (
    FlightLog,
    until,
    within,
)
from tests.test_live_source_sitl import (
    REFRESH_S,
    SPEEDUP,
    START,
    WALL_TIMEOUT,
    ZONE_AT_M,
    ZONE_HALF_M,
    _distance_to_zone,
    _events,
    fly_the_leg,
    monitor_options,
)

pytestmark = pytest.mark.sitl

PRISON_MARGIN_M = 50.0  # the default rules' prison margin
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

    pg, api, store, local = fleet
    frame = LocalFrame(*START)
    fences = FenceSet(read_fences(local), frame=frame)
    zone_frame = LocalFrame(*frame.to_wgs84(-ZONE_AT_M, 0.0))
    square = shapely.box(-ZONE_HALF_M, -ZONE_HALF_M, ZONE_HALF_M, ZONE_HALF_M)
    ring = list(zone_frame.geom_to_wgs84(square).exterior.coords)
    site = _prison_change(tmp_path / "prison.osc", ring)
    version_before = pg.sql("SELECT max(version) FROM zones")[0][0]
    rows_before = pg.sql("SELECT id, version FROM zones ORDER BY id")
    options, live = monitor_options(api.collection)

    sitl = await sitl_factory(home=f"{START[1]},{START[0]},80,270", speedup=SPEEDUP)
    log = FlightLog(frame)
    results = {}

    async def update():
        results["t_update"] = time.monotonic()
        argv = ["update", str(tmp_path / "prison.osc"), "--store", str(store), "-q"]
        results["status"] = await asyncio.to_thread(main, argv)
        results["t_written"] = time.monotonic()

    async def then():
        await until("the prison's fences",
                    lambda: [e for e in _events(log, "source_zone")
                             if str(e["zone"]).startswith(site)],
                    4 * REFRESH_S + 30, log)  # fmt: skip
        return True

    await within(fly_the_leg(sitl, frame, fences, options, live, log, update, then),
                 WALL_TIMEOUT, log)  # fmt: skip
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
