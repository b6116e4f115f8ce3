"""``monitor --tlog`` records every frame the vehicle sends as a telemetry log that
``check-flight`` reads, and ``--until-disarmed`` ends the monitor when the flight is over.
Against the scripted ArduPilot peer (tests/fake_vehicle.py) on the pymavlink link."""

from __future__ import annotations

import asyncio
import json

import pytest
import shapely.geometry
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.flights.flight_log import FlightLog
from alphafence.geo.coords import to_e7
from alphafence.monitor.observe import Observer, UntilDisarmed
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.run import run_monitor
from tests.fake_vehicle import FakeVehicle
from tests.test_monitor_onboard import FRAME, full_fences

POSITIONS = 40


class Positions(Observer):
    """Counts positions; sets ``armed_seen`` when the monitor has seen the vehicle armed."""

    def __init__(self):
        self.count = 0
        self.armed_seen = asyncio.Event()
        self.enough = asyncio.Event()

    def on_value(self, stream, t, value):
        if stream == "armed" and value:
            self.armed_seen.set()
        if stream == "position":
            self.count += 1
            if self.count >= POSITIONS:
                self.enough.set()


async def _fly(fake, seen: Positions):
    """Arm, send positions northwards until the monitor has checked them, disarm."""
    fake.armed = True
    await asyncio.wait_for(seen.armed_seen.wait(), 30)
    boot_ms, y = 60_000, 0.0
    while not seen.enough.is_set():
        lon, lat = FRAME.to_wgs84(0.0, y)
        fake._send(
            mav.MAVLink_global_position_int_message(
                boot_ms, to_e7(float(lat)), to_e7(float(lon)), 40_000, 20_000, 500, 0, 0, 0
            )
        )
        boot_ms, y = boot_ms + 100, y + 0.5
        await asyncio.sleep(0.02)  # a telemetry stream's pace, not a wait for an outcome
    fake.armed = False
    fake._send(
        mav.MAVLink_heartbeat_message(
            fake.mav_type,
            mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
            mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            fake.custom_mode,
            mav.MAV_STATE_STANDBY,
            3,
        )
    )


async def test_the_flight_is_recorded_and_the_monitor_ends_when_disarmed(tmp_path):
    tlog = tmp_path / "flight.tlog"
    seen = Positions()
    stop = asyncio.Event()
    async with FakeVehicle() as fake:
        monitor = asyncio.create_task(
            run_monitor(
                fake.url,
                full_fences(),
                MonitorOptions(onboard="off"),
                stop=stop,
                link="pymavlink",
                tlog_path=tlog,
                observers=[UntilDisarmed(stop), seen],
            )
        )
        flying = asyncio.create_task(_fly(fake, seen))
        done = await asyncio.wait_for(monitor, 60)  # ends by itself: no stop.set() here
        await flying
    assert stop.is_set() and done.engine.checks > 0
    log = FlightLog(tlog)
    positions = sum(len(c) for c in log.chunks())
    assert positions >= POSITIONS, positions  # every position the vehicle sent is in the log
    assert log.info.clock == "utc"  # stamped with UNIX time, as a ground station stamps them
    assert main(["check-flight", str(tlog), "--fences", _fences_file(tmp_path)]) == 0


def _fences_file(tmp_path):
    """The monitor's keep-out square as a fence file (lon/lat, as GeoJSON is)."""
    (record,) = full_fences().records
    feature = {
        "type": "Feature",
        "properties": {"site_id": record.site_id, "kind": "keep_out", "name": "hospital"},
        "geometry": shapely.geometry.mapping(record.geometry),
    }
    path = tmp_path / "fences.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    return str(path)


def test_a_telemetry_log_needs_the_pymavlink_link_and_a_writable_path(tmp_path, capsys):
    fences = _fences_file(tmp_path)
    base = ["monitor", "--connect", "udpin:127.0.0.1:14999", "--fences", fences]
    base += ["--allow-unsigned"]
    pytest.importorskip("mavsdk")
    assert main([*base, "--tlog", str(tmp_path / "f.tlog"), "--link", "mavsdk"]) == 2
    assert "--tlog: records the pymavlink link's frames" in capsys.readouterr().err
    bad = tmp_path / "no-such-dir" / "f.tlog"
    assert main([*base, "--tlog", str(bad), "--link", "pymavlink"]) == 2
    err = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(err) == 1 and "cannot write the telemetry log" in err[0], err
