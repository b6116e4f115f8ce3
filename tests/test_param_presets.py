"""``upload --params``: presets per vehicle with ArduPilot's own FENCE_* values, listed by
``--params list``, and refused before anything is sent to a vehicle of another type."""

import asyncio

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.fencefiles.qgc_wpl import waypoints_text
from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem
from alphafence.vehicle.params import PROFILES, VEHICLE, vehicle_kind
from tests.fake_vehicle import FakeVehicle

SQUARE = [
    FenceItem(POLYGON_EXCLUSION, 4.0, lon, lat)
    for lon, lat in [(14.50, 35.90), (14.501, 35.90), (14.501, 35.901), (14.50, 35.901)]
]
FENCE_PARAMS = {"FENCE_ENABLE": 0, "FENCE_TYPE": 7, "FENCE_ACTION": 1, "FENCE_MARGIN": 3.0}
FENCE_PARAMS["FENCE_ALT_MAX"] = 100.0


def test_params_list_prints_every_preset_and_its_parameters(capsys):
    with pytest.raises(SystemExit) as done:
        main(["upload", "--params", "list"])
    assert done.value.code == 0
    rows = {
        line.split("│")[1].strip(): line
        for line in capsys.readouterr().out.splitlines()
        if line.startswith("│") and line.split("│")[1].strip()
    }
    assert {"copter", "plane", "rover", "px4"} == set(VEHICLE.values())
    assert set(rows) == set(PROFILES)
    # FENCE_ACTION as AC_Fence.cpp documents it for each vehicle
    assert "FENCE_ACTION=4 (Brake or Land)" in rows["copter-brake"]
    assert "FENCE_ACTION=3 (SmartRTL or RTL or Land)" in rows["copter-smartrtl"]
    assert "FENCE_ACTION=6 (Guided)" in rows["plane-guided"]
    assert "FENCE_ACTION=2 (Hold)" in rows["rover-hold"]
    assert "FENCE_ACTION=1 (RTL)" in rows["plane-rtl"]
    # GF_ACTION as PX4's geofence_params.yaml documents it
    assert "GF_ACTION=2 (Hold mode)" in rows["px4-hold"]
    assert "GF_ACTION=3 (Return mode)" in rows["px4-return"]
    assert "GF_ACTION=5 (Land mode)" in rows["px4-land"]


def test_a_rover_preset_sets_no_altitude_fence():
    for name, vehicle in VEHICLE.items():
        values = PROFILES[name]
        if vehicle == "px4":
            assert set(values) >= {"GF_ACTION", "GF_SOURCE"} and values["GF_ACTION"] >= 1
            continue
        assert values["FENCE_ENABLE"] == 1 and values["FENCE_TYPE"] & 4  # polygons and circles
        if vehicle == "rover":  # Rover's FENCE_TYPE bits are 1 and 2; it has no FENCE_ALT_MAX
            assert values["FENCE_TYPE"] & 1 == 0 and "FENCE_ALT_MAX" not in values


def test_heartbeat_types_are_classed_as_pymavlink_does():
    assert vehicle_kind(mav.MAV_TYPE_HEXAROTOR) == "copter"
    assert vehicle_kind(mav.MAV_TYPE_VTOL_QUADROTOR) == "plane"
    assert vehicle_kind(mav.MAV_TYPE_SURFACE_BOAT) == "rover"
    assert vehicle_kind(mav.MAV_TYPE_SUBMARINE) is None


def upload(tmp_path, mav_type, preset, link="pymavlink"):
    path = tmp_path / "onboard.waypoints"
    path.write_text(waypoints_text(SQUARE))

    async def run():
        async with FakeVehicle(params=FENCE_PARAMS, mav_type=mav_type) as fake:
            argv = ["upload", str(path), "--connect", fake.url, "--allow-unsigned"]
            code = await asyncio.to_thread(main, [*argv, "--link", link, "--params", preset])
            return code, fake

    return asyncio.run(run())


def test_a_plane_preset_is_set_on_a_plane(tmp_path, capsys):
    code, fake = upload(tmp_path, mav.MAV_TYPE_FIXED_WING, "plane-guided")
    assert code == 0, capsys.readouterr()
    assert fake.params["FENCE_ACTION"] == 6 and fake.params["FENCE_TYPE"] == 5
    assert fake.fence


@pytest.mark.parametrize("link", ["pymavlink", "mavsdk"])
def test_a_preset_for_another_vehicle_is_refused_before_anything_is_sent(tmp_path, capsys, link):
    from alphafence.vehicle.link import NoLinkError, choose_link

    try:
        choose_link(link)
    except NoLinkError as exc:
        pytest.skip(str(exc))
    code, fake = upload(tmp_path, mav.MAV_TYPE_FIXED_WING, "copter-brake", link)
    assert code == 3
    assert not fake.received("PARAM_SET") and not fake.received("MISSION_COUNT")
    errors = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(errors) == 1, errors
    assert "copter-brake is for a copter; the vehicle is a plane" in errors[0]
    assert "plane-rtl" in errors[0]  # what fits it
