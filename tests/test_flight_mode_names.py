"""Flight modes by ArduPilot's names (GUIDED, BRAKE, LOITER, RTL, AUTO...), from the
HEARTBEAT's custom_mode by the vehicle's type, on either link and in replayed traces."""

import asyncio

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli.demo import trace_path
from alphafence.mavlink import ids
from alphafence.monitor.feeds import latest_sample
from alphafence.review.replay import Trace
from alphafence.vehicle.values import Position, ardupilot_mode, custom_mode_of, flight_mode
from tests.fake_vehicle import FakeVehicle

CASES = [  # HEARTBEAT type, custom_mode, ArduPilot's name
    (mav.MAV_TYPE_QUADROTOR, ids.COPTER_MODE_GUIDED, "GUIDED"),
    (mav.MAV_TYPE_QUADROTOR, ids.COPTER_MODE_BRAKE, "BRAKE"),
    (mav.MAV_TYPE_HEXAROTOR, ids.COPTER_MODE_LOITER, "LOITER"),
    (mav.MAV_TYPE_QUADROTOR, ids.COPTER_MODE_SMART_RTL, "SMART_RTL"),
    (mav.MAV_TYPE_FIXED_WING, ids.PLANE_MODE_LOITER, "LOITER"),
    (mav.MAV_TYPE_FIXED_WING, ids.PLANE_MODE_AUTO, "AUTO"),
    (mav.MAV_TYPE_GROUND_ROVER, ids.ROVER_MODE_HOLD, "HOLD"),
    (mav.MAV_TYPE_SURFACE_BOAT, ids.ROVER_MODE_RTL, "RTL"),
]


@pytest.mark.parametrize(("mav_type", "number", "name"), CASES)
def test_a_heartbeat_mode_is_named_as_ardupilot_names_it(mav_type, number, name):
    assert flight_mode(mav_type, number).name == name
    assert custom_mode_of(name, mav_type) == number


def test_the_pymavlink_link_reports_brake_not_hold(tmp_path):
    from alphafence.vehicle.link import open_vehicle

    async def first_mode(fake):
        async with open_vehicle(fake.url, 5.0, None, "pymavlink") as vehicle:
            async for mode in vehicle.telemetry.subscribe_flight_mode():
                return mode.name

    async def run():
        names = []
        for mav_type, number, _ in CASES[1:2] + CASES[4:5] + CASES[6:7]:
            async with FakeVehicle(mav_type=mav_type) as fake:
                fake.custom_mode = number
                names.append(await asyncio.wait_for(first_mode(fake), 10.0))
        return names

    assert asyncio.run(run()) == ["BRAKE", "LOITER", "HOLD"]


def test_mavsdk_names_reach_the_engine_as_ardupilot_names():
    class Mode:  # MAVSDK's FlightMode enum member, by its name
        name = "OFFBOARD"

    latest = dict.fromkeys(("position", "velocity", "mode", "armed", "gps"))
    latest["position"] = (1.0, Position(51.43, -0.55, 40.0, 20.0))
    latest["mode"] = (1.0, Mode())
    assert latest_sample(latest).mode == "GUIDED"
    assert [ardupilot_mode(n) for n in ("MISSION", "HOLD", "RETURN_TO_LAUNCH")] == [
        "AUTO",
        "BRAKE",
        "RTL",
    ]


def test_a_trace_recorded_with_mavsdk_names_replays_with_ardupilot_names():
    raw = trace_path().read_text()
    assert '"OFFBOARD"' in raw and '"HOLD"' in raw  # as it was recorded
    modes = {s.mode for s in Trace.read(trace_path()).samples}
    assert modes == {"GUIDED", "BRAKE"}
