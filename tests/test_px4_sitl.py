"""Fences on a real PX4 (its SITL, SIH quadrotor, from ``../shared/px4-sitl`` or $PX4_SITL),
on each vehicle link: compiled for PX4, uploaded and read back at its budget and one over it;
a fence PX4 would drop part of refused before anything is sent; PX4's presets set and read
back."""

import asyncio
import math

import numpy as np
import pytest

from alphafence.cli import main
from alphafence.fencefiles.qgc_wpl import waypoints_text
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    FenceItem,
)
from alphafence.mavlink.storage import PX4_ITEMS
from alphafence.vehicle.fence_transfer import (
    FenceTransferError,
    download_fence,
    same_items,
    upload_fence,
)
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import read_params

pytestmark = [pytest.mark.sitl, pytest.mark.px4]
HOME = (14.4775, 35.8660)  # the PX4 fixture's home (lon, lat): Luqa, north of the airport


def ring_items(command, n, radius, east=0.0, north=0.0):
    frame = LocalFrame(*HOME)
    ang = np.linspace(0, 2 * math.pi, n, endpoint=False)
    lon, lat = frame.to_wgs84(east + radius * np.cos(ang), north + radius * np.sin(ang))
    return [FenceItem(command, float(n), round(a, 7), round(b, 7)) for a, b in zip(lon, lat)]


def budget_items(total):
    """``total`` items, none holding home: a 60-gon exclusion 1 km east, then circles."""
    items = ring_items(POLYGON_EXCLUSION, 60, 100.0, east=1000.0)
    frame = LocalFrame(*HOME)
    for k in range(total - 60):
        lon, lat = frame.to_wgs84(-1000.0, 100.0 * k)
        items.append(FenceItem(CIRCLE_EXCLUSION, 30.0, round(float(lon), 7), round(float(lat), 7)))
    return items


async def test_the_budget_is_accepted_and_one_over_refused_with_the_old_fence_kept(px4, link):
    full, over = budget_items(PX4_ITEMS), budget_items(PX4_ITEMS + 1)
    # the launcher left out PX4's ground-station link: no PX4 talks to whatever listens on
    # 14550 (a ground station, another test's vehicle), as PX4 says as it starts its links
    assert px4.logged(f"remote port {14540 + px4.instance}") and not px4.logged("port 14550")
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        assert vehicle.autopilot == "px4"
        report = await upload_fence(vehicle, full, capacity=PX4_ITEMS)
        assert report.verified and report.items == 64
        with pytest.raises(FenceTransferError) as err:
            await upload_fence(vehicle, over, capacity=PX4_ITEMS)
        assert err.value.result in ("NO_SPACE", "TOO_MANY_MISSION_ITEMS")
        assert "no room for that many fence items" in str(err.value)
        assert "still holds its previous fence (64 items)" in str(err.value)
        assert same_items(full, await download_fence(vehicle)) == []


@pytest.fixture(scope="module")
def malta_fences(malta, tmp_path_factory):
    out = tmp_path_factory.mktemp("malta-px4") / "fences.geojson"
    assert main(["build", str(malta), "-o", str(out), "-q"]) == 0
    return out


async def test_a_malta_fence_compiled_for_px4_uploads_and_reads_back_identical(
    px4, link, malta_fences, capsys
):
    argv = ["upload", str(malta_fences), "--bbox", "14.46,35.84,14.50,35.88", "--distance",
            "1000", "--connect", px4.connection_url, "--allow-unsigned", "--timeout", "30"]  # fmt: skip
    assert await asyncio.to_thread(main, argv) == 0
    out = capsys.readouterr().out
    assert "the vehicle runs PX4" in out  # from its HEARTBEAT: compiled for PX4's rules
    assert "read them back identical" in out and "PX4 keeps every area" in out
    n = int(out.split("uploaded ")[1].split()[0])
    assert 10 <= n <= PX4_ITEMS
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        held = await download_fence(vehicle)
    assert len(held) == n and not px4.logged("Geofence invalid")


async def test_the_malta_box_of_the_first_report_uploads_with_home_clear(
    px4, link, malta_fences, capsys
):
    """Home at Luqa, 215 m from every keep-out fence: compiled blind to it, PX4's 64 items
    merged a 7.9 km² exclusion over it and the upload was refused. Compiled round the
    vehicle's home, every keep-out fence of the box is held and home is in none."""
    import shapely

    from alphafence.fencefiles.fence_read import read_fence_file

    from .test_home_clear import BOX, assert_clear_and_holding, far_from

    argv = ["upload", str(malta_fences), "--bbox", ",".join(map(str, BOX)),
            "--connect", px4.connection_url, "--allow-unsigned", "--timeout", "30"]  # fmt: skip
    assert await asyncio.to_thread(main, argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "home 35.86" in out and "the fence leaves them 25 m clear" in out
    assert "PX4 keeps every area" in out
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        held = await download_fence(vehicle)
    assert 10 <= len(held) <= PX4_ITEMS and not px4.logged("Geofence invalid")
    records = read_fence_file(malta_fences)
    dropped = far_from(records, shapely.box(*BOX))
    assert_clear_and_holding(records, held, dropped, "px4", HOME)


async def test_a_fence_px4_would_drop_part_of_is_refused_and_nothing_is_sent(
    px4, link, tmp_path, capsys
):
    keep_out = ring_items(POLYGON_EXCLUSION, 6, 80.0, east=600.0)
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        await upload_fence(vehicle, keep_out)
    # a keep-in 2 km north: home lies outside it
    away = ring_items(POLYGON_INCLUSION, 5, 300.0, north=2000.0)
    path = tmp_path / "away.waypoints"
    path.write_text(waypoints_text(away + keep_out))
    argv = ["upload", str(path), "--connect", px4.connection_url, "--allow-unsigned"]
    assert await asyncio.to_thread(main, argv) == 3
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(err) == 1, err
    assert "PX4 would drop 1 area of this fence" in err[0] and "nothing was sent" in err[0]
    assert "onboard inclusion polygon 1 (items 0-4) (outside)" in err[0]
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        assert same_items(keep_out, await download_fence(vehicle)) == []  # the old fence held
        # broken case: the same fence sent without the check is taken (ACK 0), and PX4 drops
        # the keep-in as it loads it, saying so only in its log
        await upload_fence(vehicle, away + keep_out)
    loop = asyncio.get_running_loop()
    deadline = loop.time() + 30.0
    while not px4.logged("Geofence invalid") and loop.time() < deadline:
        await asyncio.sleep(0.2)
    assert px4.logged("doesn't contain Home position")


async def test_px4_presets_are_set_and_read_back_and_ardupilot_ones_refused(
    px4, link, tmp_path, capsys
):
    path = tmp_path / "out.waypoints"
    path.write_text(waypoints_text(ring_items(POLYGON_EXCLUSION, 4, 50.0, east=500.0)))
    argv = ["upload", str(path), "--connect", px4.connection_url, "--allow-unsigned",
            "--timeout", "30"]  # fmt: skip
    assert await asyncio.to_thread(main, [*argv, "--params", "copter-brake"]) == 3
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(err) == 1 and "copter-brake is for ArduPilot; the vehicle runs PX4" in err[0]
    assert "px4-hold" in err[0] and "nothing was sent" in err[0]
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        assert await download_fence(vehicle) == []
    assert await asyncio.to_thread(main, [*argv, "--params", "px4-return"]) == 0
    assert "GF_ACTION=3" in capsys.readouterr().out
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        got = await read_params(
            vehicle, ["GF_ACTION", "GF_SOURCE", "GF_PREDICT", "GF_MAX_VER_DIST"]
        )
    assert got == {"GF_ACTION": 3, "GF_SOURCE": 0, "GF_PREDICT": 1, "GF_MAX_VER_DIST": 120.0}
    # and PX4's own shell says so: an integer travels byte-wise on PX4 (a read-back through the
    # same wrong encoding would agree with itself)
    assert [await px4.param(n) for n in ("GF_ACTION", "GF_PREDICT")] == ["3", "1"]


async def test_px4_integers_written_as_ardupilot_reads_them_land_wrong(px4, monkeypatch):
    # broken case: the pymavlink link's parameters encoded as for ArduPilot (value in the float)
    from alphafence.vehicle.params import apply_params
    from alphafence.vehicle.pymavlink_plugins import Param

    monkeypatch.setattr(Param, "_bytewise", property(lambda self: False))
    async with open_vehicle(px4.connection_url, 30, link="pymavlink") as vehicle:
        got = await apply_params(vehicle, {"GF_ACTION": 3})  # its read-back agrees...
    assert got.values == {"GF_ACTION": 3}
    assert await px4.param("GF_ACTION") == "1077936128"  # ...and PX4 holds 3.0's bits


async def test_a_mission_starts_on_px4_straight_into_its_mission_mode(px4, link):
    # the monitor resumes a mission with mission_raw's start; on PX4 that is its Mission mode,
    # never a pass through another (ArduPilot's AUTO number, 3, is PX4's Position mode: a
    # pilot's mode, which would make the monitor stand back)
    from alphafence.mavlink import ids
    from alphafence.vehicle.values import RawItem, px4_flight_mode
    from tests.sitl_flight import upload_mission

    frame = LocalFrame(*HOME)
    lon, lat = frame.to_wgs84(80.0, 0.0)
    rel = ids.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    def item(seq, command, x=0, y=0):
        return RawItem(seq, rel, command, int(seq == 0), 1, 0.0, 0.0, 0.0, float("nan"), x, y,
                       15.0, ids.MAV_MISSION_TYPE_MISSION)  # fmt: skip

    lat_e7, lon_e7 = round(float(lat) * 1e7), round(float(lon) * 1e7)
    mission = [item(0, ids.MAV_CMD_NAV_TAKEOFF, lat_e7 - 2000, lon_e7 - 9000),
               item(1, ids.MAV_CMD_NAV_WAYPOINT, lat_e7, lon_e7)]  # fmt: skip
    modes, sent = [], []
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        await upload_mission(vehicle, mission)
        watching = asyncio.ensure_future(_modes(vehicle, modes))
        await vehicle.action.arm()
        if vehicle.kind == "pymavlink":  # the kit's own commands: which modes it asks for
            command_long = vehicle.command_long

            async def spy(command, *params, **kw):
                sent.append((command, *params))
                return await command_long(command, *params, **kw)

            vehicle.command_long = spy
        await vehicle.mission_raw.start_mission()
        async for p in vehicle.telemetry.subscribe_position():
            if float(frame.to_local(p.longitude_deg, p.latitude_deg)[0]) > 40.0:
                break
        watching.cancel()
        await asyncio.gather(watching, return_exceptions=True)
    modes_asked = [(int(p[1]), int(p[2])) for c, *p in sent if c == ids.MAV_CMD_DO_SET_MODE]
    assert vehicle.kind != "pymavlink" or modes_asked == [(4, 4)], sent  # AUTO.MISSION only
    # and no MISSION_START, whose first item (0) PX4 would make the current one: a mission
    # resumed after a re-route would fly back to its start
    assert ids.MAV_CMD_MISSION_START not in [c for c, *_ in sent], sent
    names = [px4_flight_mode(m).name for m in modes]
    assert "MISSION" in names, names  # PX4's Mission mode
    assert not {"POSCTL", "ALTCTL", "STABILIZED", "MANUAL"} & set(names), names


async def _modes(vehicle, out):
    async for m in vehicle.messages("HEARTBEAT"):
        if m.component_id == 1 and m.fields["autopilot"] == 12:
            if not out or out[-1] != m.fields["custom_mode"]:
                out.append(m.fields["custom_mode"])


@pytest.mark.parametrize("home_in", ["west", "east"])
async def test_two_keep_in_areas_are_one_inclusion_and_its_gap_and_px4_arms_in_either(
    px4, link, tmp_path, capsys, home_in
):
    """PX4 intersects its inclusions; two keep-in areas compiled as one inclusion round them
    and an exclusion for the gap: PX4 keeps every area and arms with home in either, and by
    its model nothing between them is allowed."""
    import json

    import shapely
    import shapely.geometry

    from alphafence.fencefiles.fence_geojson import FenceRecord

    from .test_keep_in_gaps import violations

    frame = LocalFrame(*HOME)
    shift = 0.0 if home_in == "west" else -2000.0
    boxes = [shapely.box(-300 + shift, -300, 300 + shift, 300),
             shapely.box(1700 + shift, -300, 2300 + shift, 300)]  # fmt: skip
    records = [FenceRecord(f"area/{k}", "keep_in", frame.geom_to_wgs84(b))
               for k, b in enumerate(boxes)]  # fmt: skip
    features = [{"type": "Feature", "properties": {"site_id": r.site_id, "kind": "keep_in"},
                 "geometry": shapely.geometry.mapping(r.geometry)} for r in records]  # fmt: skip
    path = tmp_path / "areas.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    lon0, lat0, lon1, lat1 = shapely.total_bounds([r.geometry for r in records])
    argv = ["upload", str(path), "--bbox", f"{lon0},{lat0},{lon1},{lat1}", "--connect",
            px4.connection_url, "--allow-unsigned", "--timeout", "30", "--params", "px4-hold"]  # fmt: skip
    assert await asyncio.to_thread(main, argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "PX4 keeps every area" in out
    assert "keep-in areas compiled as one inclusion round them" in out.replace("\n", " ")
    async with open_vehicle(px4.connection_url, 30) as vehicle:
        held = await download_fence(vehicle)
        assert sum(1 for k, i in enumerate(held)
                   if i.command == POLYGON_INCLUSION and (k == 0 or held[k - 1].command != i.command)) == 1  # fmt: skip
        assert any(i.command == POLYGON_EXCLUSION for i in held)
        assert violations(records, held, "px4", HOME) == 0
        await vehicle.action.arm()  # home inside one area: PX4's geofence check passes
        from alphafence.mavlink import ids

        assert await vehicle.command_long(ids.MAV_CMD_COMPONENT_ARM_DISARM, 0.0) == 0
    assert not px4.logged("Geofence invalid")
