"""PX4's flight modes by PX4's names (as MAVSDK, PX4's SDK, names them: HOLD, MISSION, POSCTL,
RETURN_TO_LAUNCH, ...) on either link, in the engine's pilot rule and in replayed traces; and
PX4's MISSION_CURRENT, whose total counts no home item."""

import asyncio

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.monitor import engine as engine_module
from alphafence.monitor.engine import PILOT_MODES, Engine, Sample
from alphafence.monitor.feeds import latest_sample
from alphafence.monitor.options import MonitorOptions
from alphafence.review.replay import Trace
from alphafence.vehicle.values import (
    GOTO_MODE,
    MISSION_MODE,
    PX4_MODES,
    Position,
    px4_custom_mode,
)
from tests.fake_vehicle import FakeVehicle
from tests.test_monitor_engine import fences, north_run  # noqa: F401 - the fixture

PX4_PILOT = {"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED"}  # the pilot flies: PX4's docs
ARDUPILOT_NAMES = {
    name
    for table in (mavutil.mode_mapping_acm, mavutil.mode_mapping_apm, mavutil.mode_mapping_rover)
    for name in table.values()
}


def test_px4s_pilot_modes_are_pilot_modes_and_its_others_are_not():
    names = {mavsdk for _, _, mavsdk in PX4_MODES.values()}
    assert PX4_PILOT <= names
    assert PX4_PILOT <= PILOT_MODES
    assert not (names - PX4_PILOT) & PILOT_MODES  # HOLD, MISSION, RETURN_TO_LAUNCH, ...
    # a PX4 name that is also an ArduPilot mode's means the same to the pilot rule in both
    for name in (names - PX4_PILOT) & ARDUPILOT_NAMES:
        assert name not in PILOT_MODES, name
    for name in PX4_PILOT - ARDUPILOT_NAMES:  # PX4's own pilot names are no ArduPilot mode
        assert name in ("ALTCTL", "POSCTL", "STABILIZED"), name
    assert GOTO_MODE["px4"] in names and MISSION_MODE["px4"] in names


def _px4_run(fence_set, pilot_at=8.0):
    """PX4 in Mission northwards at the square; the pilot switches to Position at
    ``pilot_at`` s, then Mission resumes (the pilot's choice) before IMMINENT."""
    eng = Engine(fence_set, MonitorOptions(enforce=True, backoff_s=60))
    events = []
    for s in north_run(mode="MISSION"):
        if pilot_at <= s.t < pilot_at + 1.0:
            s.mode = "POSCTL"
        events += eng.step(s)
    return events


def test_a_px4_pilot_taking_position_mode_is_backed_off_from(fences):  # noqa: F811
    events = _px4_run(fences)
    (change,) = [e for e in events if e["event"] == "pilot_mode_change"]
    assert change["mode"] == "POSCTL"
    withheld = [e for e in events if e["event"] == "action_withheld"]
    assert withheld and not [e for e in events if e["event"] == "action"]


def test_broken_without_px4s_names_the_monitor_fights_the_pilot(fences, monkeypatch):  # noqa: F811
    ardupilot_only = PILOT_MODES - {"ALTCTL", "POSCTL", "STABILIZED"}
    monkeypatch.setattr(engine_module, "PILOT_MODES", ardupilot_only)
    events = _px4_run(fences)
    assert not [e for e in events if e["event"] == "pilot_mode_change"]
    assert [e["action"] for e in events if e["event"] == "action"][:1] == ["brake"]


def test_the_engine_reads_px4s_names_from_either_link():
    class Mode:  # MAVSDK's FlightMode member
        name = "HOLD"

    latest = dict.fromkeys(("position", "velocity", "mode", "armed", "gps"))
    latest["position"] = (1.0, Position(35.866, 14.4775, 80.0, 20.0))
    latest["mode"] = (1.0, Mode())
    assert latest_sample(latest, "px4").mode == "HOLD"
    assert latest_sample(latest, "ardupilot").mode == "BRAKE"  # MAVSDK's name for it


async def _modes_and_progress(fake, custom_modes, currents):
    from alphafence.vehicle.link import open_vehicle

    async with open_vehicle(fake.url, 5.0, None, "pymavlink") as vehicle:
        modes = []
        async for mode in vehicle.telemetry.subscribe_flight_mode():
            if not modes or modes[-1] != mode.name:
                modes.append(mode.name)
            if len(modes) == len(custom_modes):
                break
            fake.custom_mode = custom_modes[len(modes)]
        progress = []
        stream = vehicle.mission_raw.subscribe_mission_progress()
        for seq, total in currents:
            fake._send(mav.MAVLink_mission_current_message(seq, total))
            p = await asyncio.wait_for(stream.__anext__(), 10.0)
            progress.append((p.current, p.total))
        await stream.aclose()
        return vehicle.autopilot, modes, progress


def test_the_pymavlink_link_names_px4s_modes_as_mavsdk_does():
    # PX4 counts no home item; 65535 is no mission at all (a pymavlink too old for the total
    # sends MISSION_CURRENT without it: modes only)
    with_total = "total" in mav.MAVLink_mission_current_message.fieldnames
    currents = [(0, 65535), (1, 3)] if with_total else []

    async def run():
        names = ("AUTO.LOITER", "AUTO.MISSION", "POSCTL", "AUTO.RTL")
        async with FakeVehicle(autopilot=mav.MAV_AUTOPILOT_PX4) as fake:
            fake.custom_mode = px4_custom_mode(names[0])
            modes = [px4_custom_mode(n) for n in names]
            return await asyncio.wait_for(_modes_and_progress(fake, modes, currents), 30.0)

    autopilot, modes, progress = asyncio.run(run())
    assert autopilot == "px4"
    assert modes == ["HOLD", "MISSION", "POSCTL", "RETURN_TO_LAUNCH"]
    assert progress == ([(0, 0), (1, 3)] if with_total else [])


def test_a_px4_trace_replays_with_px4s_names(tmp_path):
    samples = [Sample(0.1 * k, 35.866, 14.4775, 20.0, mode=m) for k, m in enumerate(
        ("MISSION", "HOLD", "POSCTL"))]  # fmt: skip
    path = tmp_path / "px4.trace"
    path.write_text(Trace("PX4 SITL", samples=samples, autopilot="px4").to_text())
    read = Trace.read(path)
    assert read.autopilot == "px4" and [s.mode for s in read.samples] == [
        "MISSION",
        "HOLD",
        "POSCTL",
    ]
    # broken case: the same samples read as ArduPilot's take ArduPilot's names
    text = path.read_text().replace(', "autopilot": "px4"', "")
    assert [s.mode for s in Trace.from_text(text).samples] == ["AUTO", "BRAKE", "POSHOLD"]
    bad = path.read_text().replace('"autopilot": "px4"', '"autopilot": "inav"')
    with pytest.raises(Exception, match="line 1: autopilot 'inav'"):
        Trace.from_text(bad, "px4.trace")
