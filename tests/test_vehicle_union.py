"""Whether a vehicle reads its inclusions as their union, asked of a vehicle as the monitor
asks it (``vehicle_union``), against ArduPilot's rule written from its source: AC_Fence reads
``FENCE_OPTIONS`` bit 1 (``INCLUSION_UNION``, value 2) from 4.5.0 on; before, and on PX4, the
inclusions are intersected whatever the parameter says."""

from __future__ import annotations

import asyncio

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import vehicle_union

from .fake_vehicle import FakeVehicle

CASES = [
    # (autopilot, firmware, FENCE_OPTIONS or None for a firmware without the parameter)
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), 2.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 5, 0), 3.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), 0.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), 1.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), 4.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 4, 4), 2.0),
    (mav.MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 3, 0), None),
    (mav.MAV_AUTOPILOT_PX4, (1, 15, 0), 2.0),
]


def source_rule(autopilot, firmware, options):
    """AC_Fence: ``option_enabled(OPTIONS::INCLUSION_UNION)`` with INCLUSION_UNION = 1U << 1,
    a parameter added in 4.5.0; PX4's Geofence has no such option."""
    if autopilot != mav.MAV_AUTOPILOT_ARDUPILOTMEGA or options is None:
        return False
    return firmware >= (4, 5, 0) and (int(options) >> 1) & 1 == 1


async def ask(autopilot, firmware, options):
    params = {"FENCE_ENABLE": 0.0, "FENCE_TYPE": 7.0}
    if options is not None:
        params["FENCE_OPTIONS"] = options
    async with FakeVehicle(params=params, firmware=firmware, autopilot=autopilot) as fake:
        async with open_vehicle(fake.url, 10.0, None, "pymavlink") as vehicle:
            return await vehicle_union(vehicle)


@pytest.mark.parametrize(("autopilot", "firmware", "options"), CASES)
def test_the_vehicle_reads_its_inclusions_as_the_source_says(autopilot, firmware, options):
    assert asyncio.run(ask(autopilot, firmware, options)) is source_rule(
        autopilot, firmware, options
    )


def test_the_cases_tell_union_from_every_simpler_rule():
    # the cases are chosen so that no simpler rule passes them: the bit alone, the version
    # alone, any option set, or union always
    truth = [source_rule(*c) for c in CASES]
    for wrong in (
        lambda a, f, o: o is not None and int(o) & 2 != 0,
        lambda a, f, o: f >= (4, 5, 0),
        lambda a, f, o: bool(o),
        lambda a, f, o: True,
    ):
        assert [bool(wrong(*c)) for c in CASES] != truth
