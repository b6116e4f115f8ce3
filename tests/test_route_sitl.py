"""A routed mission flies around a keep-out zone in real copter SITL without a fence breach.

A keep-out square (100 m x 100 m, 150-250 m north of home) is a ``FenceRecord``; the kit's
router (``FenceRoadmap``, clearance 20 m) plans a mission from home to a point 400 m north,
on the far side of it, and ``mission_items`` turns the route into the same QGC items the
``alphafence route`` CLI writes: takeoff, waypoints out, the same waypoints back (the default
there-and-back: the final RTL flies straight home, so a one-way mission would end by crossing
the square), RTL. The items are uploaded with the link's ``mission_raw``, the square itself
with the kit's fence uploader and the ``copter-rtl`` parameters (FENCE_ACTION 1), and the copter
is armed and flown in AUTO until it has landed back home.

The test asserts that the copter reached the far side, that every FENCE_STATUS said
breach_status 0, that the mode stayed AUTO (a fence breach would switch it to RTL mode; the
mission's own RTL item runs inside AUTO), that no "fence breached" STATUSTEXT came, and that
every position reported stayed outside the square and nearly the clearance away from it.

ArduPilot conventions (checked by downloading the mission after the upload): mission item 0 is
home, and ``mission_raw`` (either link's) passes items through unchanged (no home is added: as many
items come back as were sent), so the list starts with a home item (frame GLOBAL, NAV_WAYPOINT;
ArduPilot answers with its own home there) and the kit's items follow from seq 1. The RTL item
comes back in frame 0 instead of 2 (ArduPilot stores no frame for it). ``start_mission`` is, on
either link, a mode change to AUTO (MISSION); sent to the armed copter on the ground, the mission's
own NAV_TAKEOFF takes off ("Mission: 1 Takeoff") with no throttle or GUIDED takeoff.

Measured (egham, speedup 5, 3 runs, two of them side by side; wall-clock seconds, x5 for sim
time): the route is 432 m each way (20.1 m planned clearance, past the square's west side),
16 items; AUTO start to 18 m 2.44 s, to the far side (y > 350 m) 14.8 s, back home 28.8 s,
landed and disarmed 37.5 s; farthest north 399.3 m; least distance of any reported position
to the square 20.0-20.1 m (near its north-west corner);
breach_status 0 in every FENCE_STATUS; the mode stayed MISSION (AUTO) throughout. The test
takes about 46 s wall, SITL start included.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import shapely

from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import mission_items
from alphafence.geo.coords import to_e7
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_RETURN_TO_LAUNCH as NAV_RETURN_TO_LAUNCH,
)
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_TAKEOFF as NAV_TAKEOFF,
)
from alphafence.mavlink.ids import (
    MAV_CMD_NAV_WAYPOINT as NAV_WAYPOINT,
)
from alphafence.mavlink.ids import MAV_FRAME_GLOBAL as FRAME_GLOBAL
from alphafence.mavlink.ids import MAV_MISSION_TYPE_MISSION as MISSION_TYPE_MISSION
from alphafence.route import FenceRoadmap
from alphafence.vehicle.fence_transfer import upload_fence
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import PROFILES, apply_params
from tests.sitl_flight import (
    ALTITUDE,
    ARM_TIMEOUT,
    FlightLog,
    ask_fence_status,
    exclusion_items,
    retry,
    square_local,
    until,
    unwatch,
    upload_mission,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

EGHAM = {"home": "egham", "speedup": 5}

# the keep-out square, in metres east (x) / north (y) of home
GOAL_NORTH = 400.0  # the far side
FAR_SIDE = 350.0  # "reached the far side": north of this
CLEARANCE = 20.0
TRACKING = 5.0  # metres the copter may stray from the planned legs towards the square

WALL_TIMEOUT = 120.0  # the whole flight, from connecting to the vehicle


def _keep_out(frame: LocalFrame) -> FenceRecord:
    return FenceRecord("square", "keep_out", frame.geom_to_wgs84(square_local()))


def to_mission_raw(items, home):
    """QGC SimpleItems (``mission_items``) -> raw mission items, home first (seq 0)."""
    from alphafence.vehicle.values import RawItem

    raw = [
        RawItem(
            seq=0,
            frame=FRAME_GLOBAL,
            command=NAV_WAYPOINT,
            current=0,
            autocontinue=1,
            param1=0.0,
            param2=0.0,
            param3=0.0,
            param4=0.0,
            x=to_e7(home.lat),
            y=to_e7(home.lon),
            z=float(home.alt),
            mission_type=MISSION_TYPE_MISSION,
        )
    ]
    for seq, it in enumerate(items, start=1):
        p = [0.0 if v is None else float(v) for v in it["params"]]
        raw.append(
            RawItem(
                seq=seq,
                frame=int(it["frame"]),
                command=int(it["command"]),
                current=1 if seq == 1 else 0,
                autocontinue=1 if it["autoContinue"] else 0,
                param1=p[0],
                param2=p[1],
                param3=p[2],
                param4=p[3],
                x=to_e7(p[4]),
                y=to_e7(p[5]),
                z=p[6],
                mission_type=MISSION_TYPE_MISSION,
            )
        )
    return raw


@pytest.mark.parametrize("sitl", [EGHAM], indirect=True)
async def test_routed_mission_flies_around_the_keep_out_without_a_breach(sitl):
    log = FlightLog(LocalFrame(sitl.home.lon, sitl.home.lat))
    await within(_fly_the_route(sitl, log), WALL_TIMEOUT, log)


async def _fly_the_route(sitl, log: FlightLog):
    home = sitl.home
    frame = log.frame
    square = square_local()

    # -- the plan: home to 400 m north around the square, there and back, then RTL
    start = (home.lon, home.lat)
    lon, lat = frame.to_wgs84(0.0, GOAL_NORTH)
    goal = (float(lon), float(lat))
    roadmap = FenceRoadmap([_keep_out(frame)], clearance=CLEARANCE, extra_lonlat=[start, goal])
    route, lonlat = roadmap.route(start, goal)
    assert route.min_clearance_m >= CLEARANCE - 0.5, route.min_clearance_m
    items = mission_items(lonlat, ALTITUDE)  # fly_back: RTL only from the start
    assert items[0]["command"] == NAV_TAKEOFF and items[-1]["command"] == NAV_RETURN_TO_LAUNCH
    planned = np.column_stack(frame.to_local(lonlat[:, 0], lonlat[:, 1]))
    legs = shapely.linestrings(np.stack([planned[:-1], planned[1:]], axis=1))
    planned_clearance = float(min(shapely.distance(legs, square)))
    assert planned_clearance >= CLEARANCE - 0.5, planned_clearance
    raw = to_mission_raw(items, home)

    async with open_vehicle(sitl.connection_url) as vehicle:
        log.texts = vehicle.texts
        action = vehicle.action
        watchers = watch(log, vehicle, "positions", "modes", "armed", "fence", "progress")
        try:
            # -- the fence and its parameters, the mission, each read back
            report = await upload_fence(vehicle, exclusion_items(frame))
            assert report.verified and report.items == 4
            params = await apply_params(vehicle, PROFILES["copter-rtl"])
            assert params.values["FENCE_ENABLE"] == 1 and params.values["FENCE_ACTION"] == 1

            await upload_mission(vehicle, raw)
            got = await vehicle.mission_raw.download_mission()
            got = sorted({int(r.seq): r for r in got}.values(), key=lambda r: r.seq)
            assert len(got) == len(raw), f"{len(raw)} items sent, {len(got)} read back"
            for sent, back in zip(raw[1:], got[1:]):
                assert back.command == sent.command, (sent, back)
                if sent.command != NAV_RETURN_TO_LAUNCH:  # it comes back in frame 0, no position
                    assert back.frame == sent.frame, (sent, back)
                assert abs(back.x - sent.x) <= 1 and abs(back.y - sent.y) <= 1, (sent, back)
                assert abs(back.z - sent.z) < 0.01, (sent, back)
            print(f"\nitem 0 sent {raw[0]}\nitem 0 read back {got[0]}")

            await vehicle.telemetry.set_rate_position(10.0)
            await ask_fence_status(vehicle, 2.0)
            await until("a FENCE_STATUS", lambda: log.fence, 15, log)
            await until("a position", lambda: log.positions, 15, log)
            assert log.fence[-1][1]["breach_status"] == 0, "breached on the ground at home"

            # -- arm, then AUTO: the mission's NAV_TAKEOFF takes off
            await retry("arming", action.arm, ARM_TIMEOUT)
            t_start = time.monotonic()
            await vehicle.mission_raw.start_mission()
            await until("AUTO", lambda: log.mode() == "AUTO", 5, log)
            t_up = await until(
                "climb to 90% of the mission altitude",
                lambda: log.positions[-1][3] >= 0.9 * ALTITUDE,
                30,
                log,
            )
            t_far = await until(
                "the far side", lambda: log.positions[-1][2] > FAR_SIDE, 60, log, poll=0.02
            )
            t_back = await until(
                "back home", lambda: np.hypot(*log.positions[-1][1:3]) < 10.0, 60, log
            )
            t_landed = await until("landed and disarmed", lambda: not log.is_armed(), 40, log)
        finally:
            await unwatch(watchers)

    flown = [p for p in log.positions if t_start <= p[0] <= t_landed]
    xy = np.array([p[1:3] for p in flown])
    distances = shapely.distance(shapely.points(xy), square)
    worst = int(np.argmin(distances))
    fence_in_flight = [f for t, f in log.fence if t >= t_start]
    modes_in_flight = [m for t, m in log.modes if t_start <= t <= t_landed]
    said = [text for t, text in vehicle.texts if t >= t_start]
    farthest = float(xy[:, 1].max())
    print(
        f"\nroute: {route.length_m:.0f} m out, {len(items)} items, planned clearance "
        f"{planned_clearance:.1f} m; flight: takeoff {t_up - t_start:.2f} s, far side "
        f"{t_far - t_start:.2f} s, home {t_back - t_start:.2f} s, landed "
        f"{t_landed - t_start:.2f} s (wall, speedup {sitl.speedup:g}); farthest north "
        f"{farthest:.1f} m; min distance to the square {distances[worst]:.1f} m at "
        f"x={xy[worst, 0]:.1f} y={xy[worst, 1]:.1f}; {len(fence_in_flight)} FENCE_STATUS, "
        f"breach_status {sorted({f['breach_status'] for f in fence_in_flight})}; modes "
        f"{modes_in_flight}; last progress {log.progress[-1][1:]} | "
        f"{'; '.join(said)}"
    )

    assert farthest > FAR_SIDE
    assert log.progress[-1][1:] == (len(raw), len(raw)), log.progress[-1]  # all items done
    assert fence_in_flight and all(f["breach_status"] == 0 for f in fence_in_flight), [
        f for f in fence_in_flight if f["breach_status"]
    ]
    assert "RTL" not in modes_in_flight, modes_in_flight
    assert not any("fence" in text.lower() and "breach" in text.lower() for text in said), said
    assert not any(shapely.intersects(shapely.points(xy), square))
    assert distances[worst] >= CLEARANCE - TRACKING, (distances[worst], xy[worst])
