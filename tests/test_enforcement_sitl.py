"""ArduPilot alone keeps a copter out of a restricted zone behind a kit-built fence: real copter
SITL, flown straight at the zone in GUIDED, no companion monitor.

The zone is a hospital's grounds (an 80 m wide polygon, its near edge 200 m north of home),
or the same polygon as an ED-269 prohibited geozone (the rules' tightest keep-out margin). The
kit builds its fence (``build_fences`` with the default rules: keep-out, the category's
margin), compiles it for a Copter's storage (``compile_fences``) and uploads it with the
``copter-brake`` parameters (FENCE_ACTION 4: brake or land; or ``copter-rtl``, 1: RTL), each
read back. The copter takes off to 20 m in GUIDED and is sent at the zone, to a point beyond
it (a GUIDED target inside an exclusion is ignored), at 5 or 10 m/s. ArduPilot declares the
breach as it crosses the fence and switches to BRAKE (RTL); the test waits for the copter to
stand still (to be back out of the fence) and measures, from every GLOBAL_POSITION_INT, with
geodesic distances (pyproj Geod, WGS84), how deep it got past the fence it holds and how close
it came to the zone itself. It asserts that ArduPilot acted (a breach reported, then the
mode), that it went no deeper past the fence than the kit documents for the speed
(``alphafence.vehicle.params.STOP_OVERSHOOT_M``), and that the margin, at least what the kit
documents the speed needs (``MARGIN_FOR_SPEED_M``), absorbed it (never inside the zone).

Measured (egham, speedup 5, ``+`` quad, FENCE_ACTION 4, FENCE_MARGIN 2, GLOBAL_POSITION_INT
at 10 Hz of sim time): the breach is reported within 0.7 m of the fence (the last position
before the report) and BRAKE 0.03 s of sim time after it; the copter stands still about 4.5 s
(5 m/s) and 5 s (10 m/s) of sim time later, 9.3-9.4 m (5 m/s, 6 runs) and 21.0-21.3 m
(10 m/s, 12 runs) past the fence; the same at speedup 1 (21.1 m). With FENCE_ACTION 1 (RTL)
6.6 m (5 m/s) and 21.2-21.8 m (10 m/s, 6 runs). The hospital's 30 m margin keeps the copter
21.5 m (5 m/s) and 9-9.8 m (10 m/s) from the zone, the geozone's 25 m 4.4-4.7 m (10 m/s); with
the geozone's former 10 m it would have ended about 11 m inside the zone.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pyproj
import pytest
import shapely

from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.coords import from_e7
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink import ids
from alphafence.mavlink.items import POLYGON_EXCLUSION
from alphafence.mavlink.storage import PROFILES as STORAGE
from alphafence.onboard.compile import compile_fences
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import MARGIN_FOR_SPEED_M, STOP_OVERSHOOT_M
from alphafence.zones.features import Feature
from tests.sitl_flight import (
    ALTITUDE,
    FlightLog,
    fence_and_telemetry,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

EGHAM = {"home": "egham", "speedup": 5}
GEOD = pyproj.Geod(ellps="WGS84")

# The hospital's grounds, metres east (x) / north (y) of home: the near edge square to the
# track (the worst case: the whole overshoot goes into the margin), the rest irregular.
ZONE_XY = [(-40.0, 200.0), (40.0, 200.0), (55.0, 240.0), (10.0, 265.0), (-35.0, 250.0)]
HOSPITAL = {"amenity": "hospital", "name": "St. Egham's"}
PROHIBITED = {"ed269:restriction": "PROHIBITED"}  # an ED-269 geozone: the tightest keep-out
TARGET_NORTH = 600.0  # beyond the zone and its fence
STOPPED_MPS = 0.2  # standing still: horizontal speed under this
HELD_FIXES = 20  # positions after standing still, to see that it stays stopped (2 s of sim time)
WALL_TIMEOUT = 180.0  # the whole flight: a hang fails, it is no bound on how long it takes
STEP_DEG = 2e-6  # boundaries sampled at most 0.27 m apart: a distance reads at most 0.14 m long


def kit_fence(home, rules, tags):
    """The zone (lon/lat polygon), its keep-out fence as the kit builds it, and the items the
    kit compiles from it for a Copter, with the rule that made it."""
    frame = LocalFrame(home.lon, home.lat)
    xs, ys = np.array(ZONE_XY).T
    zone = shapely.Polygon(np.column_stack(frame.to_wgs84(xs, ys)))
    rule = rules.match(tags.get, "area")
    result = build_fences([Feature(zone, tags, "way/1", "test", rule)], rules, BuildOptions())
    fence = next(f for f in result.fences if f.kind == "keep_out")
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    path = shapely.LineString([frame.to_wgs84(0.0, 0.0), frame.to_wgs84(0.0, TARGET_NORTH)])
    compiled = compile_fences(records, path, STORAGE["copter"], distance_m=1000)
    return zone, fence, compiled.items, rule


def onboard_polygon(items):
    """The exclusion polygon the vehicle holds, lon/lat (ArduPilot reads its edges as straight
    lines in lon/lat, as shapely does here)."""
    assert items and all(i.command == POLYGON_EXCLUSION for i in items), items
    return shapely.Polygon([(i.lon, i.lat) for i in items])


def geodesic_to_boundary(polygon, lon, lat):
    """Geodesic distance (m) from each position to ``polygon``'s boundary, its edges straight
    in lon/lat, sampled every STEP_DEG; negative outside, positive inside."""
    ring = shapely.get_coordinates(shapely.segmentize(polygon.boundary, STEP_DEG))
    lon, lat = np.asarray(lon, float), np.asarray(lat, float)
    out = np.empty(lon.size)
    for k, (x, y) in enumerate(zip(lon, lat)):
        _, _, d = GEOD.inv(np.full(len(ring), x), np.full(len(ring), y), ring[:, 0], ring[:, 1])
        out[k] = d.min()
    return np.where(shapely.contains_xy(polygon, lon, lat), out, -out)


async def fly_at_the_zone(sitl, log, items, speed, fixes, params="copter-brake"):
    """Upload ``items`` and ``params``, take off and fly GUIDED at ``speed`` at the zone until
    ArduPilot has braked the copter to a standstill (FENCE_ACTION 4) or flown it back out of
    the fence (RTL); ``fixes`` collects every GLOBAL_POSITION_INT as (t, lon, lat, vx, vy).
    Returns the times of the goto and of the breach."""
    frame = log.frame
    async with open_vehicle(sitl.connection_url) as vehicle:
        log.texts = vehicle.texts
        sysid = await vehicle.system_id()

        async def positions():
            async for m in vehicle.messages("GLOBAL_POSITION_INT"):
                if m.system_id == sysid:
                    f = m.fields
                    lon, lat = from_e7(f["lon"]), from_e7(f["lat"])
                    fixes.append((time.monotonic(), lon, lat, f["vx"], f["vy"]))

        watchers = watch(log, vehicle, "positions", "modes", "custom_modes", "fence")
        watchers.append(asyncio.create_task(positions()))
        try:
            await fence_and_telemetry(vehicle, log, items, params=params)
            await take_off(vehicle.action, log)
            assert not log.first_breach(), "breach before the vehicle was sent anywhere"
            lon, lat = frame.to_wgs84(0.0, TARGET_NORTH)
            await vehicle.action.goto_location(float(lat), float(lon), sitl.home.alt + ALTITUDE)
            # after the goto: GUIDED's first target after the takeoff resets WPNAV_SPEED
            await vehicle.action.set_current_speed(speed)
            t_goto = time.monotonic()
            await until("FENCE_STATUS breach", log.first_breach, 90, log, poll=0.01)
            t_breach = log.first_breach()[0]
            want = ids.COPTER_MODE_BRAKE if params == "copter-brake" else ids.COPTER_MODE_RTL
            await until(
                f"mode {want} after the breach",
                lambda: log.custom_modes[-1][1] == want,
                30,
                log,
                poll=0.01,
            )
            if want == ids.COPTER_MODE_BRAKE:
                await until(
                    "standing still in BRAKE",
                    lambda: (
                        fixes[-1][0] > t_breach and np.hypot(*fixes[-1][3:]) < STOPPED_MPS * 100
                    ),
                    60,
                    log,
                )
                n = len(fixes)
                await until(
                    "positions after stopping", lambda: len(fixes) >= n + HELD_FIXES, 30, log
                )
            else:
                polygon = onboard_polygon(items)
                await until(
                    "back out of the fence",
                    lambda: (
                        fixes[-1][0] > t_breach
                        and not shapely.contains_xy(polygon, fixes[-1][1], fixes[-1][2])
                    ),
                    60,
                    log,
                )
            return t_goto, t_breach
        finally:
            await unwatch(watchers)


def measure(zone, fence, items, fixes, t_goto, t_breach):
    """What the flight did, from its positions after the goto: speed before the breach (m/s),
    depth at the breach report and deepest past the onboard fence and the kit's fence (m),
    least distance to the zone (m, negative inside it)."""
    t, lon, lat, vx, vy = (np.array(c) for c in zip(*[f for f in fixes if f[0] >= t_goto]))
    onboard = geodesic_to_boundary(onboard_polygon(items), lon, lat)
    kit = geodesic_to_boundary(fence.geometry, lon, lat)
    to_zone = -geodesic_to_boundary(zone, lon, lat)
    before = t <= t_breach
    return {
        "speed": float(np.hypot(vx, vy)[before].max() / 100.0),
        "at_breach": float(onboard[before][-1]),
        "past_onboard": float(onboard.max()),
        "past_fence": float(kit.max()),
        "to_zone": float(to_zone.min()),
    }


@pytest.mark.parametrize(
    "params, speed, tags",
    [
        ("copter-brake", 5.0, HOSPITAL),
        ("copter-brake", 10.0, HOSPITAL),
        ("copter-rtl", 10.0, HOSPITAL),
        ("copter-brake", 10.0, PROHIBITED),
    ],
    ids=["brake-5-hospital", "brake-10-hospital", "rtl-10-hospital", "brake-10-geozone"],
)
@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_arducopter_stops_before_a_kit_built_zone(sitl, rules, params, speed, tags):
    zone, fence, items, rule = kit_fence(sitl.home, rules, tags)
    assert rule.kind == "keep_out" and fence.margin_m == rule.margin_m
    assert rule.margin_m >= MARGIN_FOR_SPEED_M[speed]  # what the kit documents for the speed
    log = FlightLog(LocalFrame(sitl.home.lon, sitl.home.lat))
    fixes = []
    t_goto, t_breach = await within(
        fly_at_the_zone(sitl, log, items, speed, fixes, params), WALL_TIMEOUT, log
    )
    m = measure(zone, fence, items, fixes, t_goto, t_breach)
    said = "; ".join(text for _, text in log.texts)
    print(
        f"\n{params} {speed:g} m/s ({rule.category}, margin {rule.margin_m:g} m): flew "
        f"{m['speed']:.1f} m/s, breach reported {m['at_breach']:+.2f} m past the onboard fence, "
        f"deepest {m['past_onboard']:.2f} m past it ({m['past_fence']:.2f} m past the kit's "
        f"fence), closest to the zone {m['to_zone']:.2f} m | {said}"
    )
    assert 0.9 * speed < m["speed"] < 1.1 * speed, f"{m['speed']:.1f} m/s on the way in"
    assert m["past_onboard"] > 0, "ArduPilot acted before the fence: nothing was measured"
    # the overshoot the kit documents for this speed holds, and the margin absorbed it
    assert m["past_onboard"] <= STOP_OVERSHOOT_M[speed], f"{m['past_onboard']:.1f} m past"
    assert m["to_zone"] > 0, f"entered the zone: {-m['to_zone']:.1f} m deep"
