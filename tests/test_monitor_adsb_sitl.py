"""Simulated ADS-B traffic from ArduPilot SITL (SIM_ADSB_*) reaches the monitor as
ADSB_VEHICLE messages, becomes dynamic fences, and raises a traffic conflict alert.

How SITL's traffic gets to the ground station (ArduPilot libraries/SITL/SIM_ADSB.cpp,
libraries/AP_HAL_SITL/UARTDriver.cpp, libraries/GCS_MAVLink/MAVLink_routing.cpp):

- ``SIM_ADSB_COUNT`` >= 0 turns SITL's SERIAL1 into the simulated ADS-B receiver, whatever
  ``--serial1`` says (the launcher's ``none`` included). It waits for the autopilot's heartbeat
  on that port (SERIAL1 is MAVLink by default) and from 10 s of simulated time on sends one
  ADSB_VEHICLE per simulated aircraft per simulated second (sysid 1, compid 156 ADSB).
- With ``ADSB_TYPE`` 0 (ArduPilot's ADS-B library off) the autopilot's MAVLink router forwards
  those broadcast messages unchanged to every other link: SERIAL0, ours. (With the library on,
  they are not forwarded but re-sent on the SRx_ADSB stream, filtered by ADSB_LIST_RADIUS and
  ADSB_LIST_ALT.) No stream rate or message interval is needed.
- Each aircraft spawns at a normally distributed offset (standard deviation
  ``SIM_ADSB_RADIUS`` m, per axis) from the vehicle, at ``SIM_ADSB_ALT`` m (the reported
  ADSB_VEHICLE altitude, taken as AMSL by the monitor), with a velocity drawn per axis from
  N(5, 20) m/s and a vertical speed from N(3, 3) m/s up (rand_normal(mean, stddev)); it
  respawns (new ICAO address) once farther than ``SIM_ADSB_RADIUS`` from the vehicle.
  With a 100 m radius and an altitude 10 m above home (egham, 20 m AMSL) an aircraft is inside
  the monitor's 150 m x +-50 m traffic cylinder from its first report until it has climbed
  40 m: a conflict at once (at t_cpa 0).

The vehicle stays on the ground; the monitor's only fence is a small keep-out 1 km away, so
traffic is the only thing it can report.
"""

from __future__ import annotations

import asyncio
import time

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import alert_text
from alphafence.monitor.observe import Observer
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle

pytestmark = pytest.mark.sitl

HOME_ALT_AMSL = 20.0  # egham, kit/alphafence/data/sitl/homes.toml
ADSB_PARAMS = {
    "SIM_ADSB_COUNT": 3,  # simulated aircraft (>= 0 also makes SERIAL1 the simulated receiver)
    "SIM_ADSB_RADIUS": 100,  # m, spawn spread and respawn distance from the vehicle
    "SIM_ADSB_ALT": HOME_ALT_AMSL + 10,  # m, the reported altitude
    "SIM_ADSB_TYPES": 1,  # the "shortcut" MAVLink receiver (ArduPilot's default)
    "ADSB_TYPE": 0,  # ADS-B library off: ADSB_VEHICLE is forwarded to the GCS link as is
}
SITL_OPTIONS = {"home": "egham", "speedup": 5, "param_values": ADSB_PARAMS}
WALL_TIMEOUT = 90.0


def _far_keep_out(frame: LocalFrame) -> FenceSet:
    return FenceSet(
        [
            FenceRecord(
                "test/far", "keep_out", frame.geom_to_wgs84(shapely.box(1000, 1000, 1100, 1100))
            )
        ]
    )


async def _watch(sitl):
    """Run the monitor until it reports a traffic conflict; what it saw, with wall times."""
    frame = LocalFrame(sitl.home.lon, sitl.home.lat)
    seen = {"reports": 0, "first_report": None, "keys": set(), "alts": []}
    async with open_vehicle(sitl.connection_url) as vehicle:
        t0 = time.monotonic()
        log = EventLog()

        class Counted(Observer):  # count every ADSB_VEHICLE the runner hands the engine
            def on_value(self, stream, t, value):
                if stream != "adsb":
                    return
                seen["reports"] += 1
                seen["keys"].add(str(value["key"]))
                seen["alts"].append(value["alt_amsl_m"])
                if seen["first_report"] is None:
                    seen["first_report"] = t

        monitor = Monitor(
            vehicle,
            _far_keep_out(frame),
            MonitorOptions(enforce=False),
            log,
            observers=[Counted()],
        )
        engine = monitor.engine
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            while not any(e["event"] == "traffic_conflict" for e in log.events):
                assert not task.done(), f"the monitor stopped: {log.events}"
                await asyncio.sleep(0.05)
            t_conflict = time.monotonic()
            # the conflict's alert runs in a task of its own, spawned with the event: until it
            # (and any other then under way) has ended, so that a failure would be logged
            if monitor.pending:
                await asyncio.wait(set(monitor.pending))
            aircraft = dict(engine.traffic.aircraft)
            # and the vehicle's own positions go on being checked beside the traffic (the
            # conflict may come before ten of them on a fast start)
            while engine.checks < 10:
                assert not task.done(), f"the monitor stopped: {log.events}"
                await asyncio.sleep(0.05)
        finally:
            stop.set()
            await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 5)
            await log.close()
    return monitor, list(log.events), seen, aircraft, t0, t_conflict


@pytest.mark.parametrize("sitl", [SITL_OPTIONS], indirect=True)
async def test_sitl_adsb_traffic_raises_a_conflict(sitl):
    t_ready = time.monotonic()
    try:
        monitor, events, seen, aircraft, t0, t_conflict = await asyncio.wait_for(
            _watch(sitl), WALL_TIMEOUT
        )
    except asyncio.TimeoutError:
        pytest.fail(f"no traffic conflict within {WALL_TIMEOUT:g} s\n{sitl.log_tail()}")

    assert not [e for e in events if e["event"] == "adsb_unavailable"], events
    assert seen["reports"] >= 1 and aircraft, "no ADSB_VEHICLE reached the engine"
    conflicts = [e for e in events if e["event"] == "traffic_conflict"]
    first = conflicts[0]
    assert first["aircraft"] in seen["keys"], (first, seen["keys"])
    assert first["callsign"].startswith("SIM"), first  # SITL names its traffic SIM<ICAO>
    text = alert_text(first)
    assert text.startswith("AF TRAFFIC"), text
    assert first["aircraft"] in text or first["callsign"] in text, text
    assert not [e for e in events if e["event"] == "alert_failed"], events
    # the vehicle sits at home, the only fence is 1 km away: traffic is all there is to report
    assert not [e for e in events if e["event"] in ("level", "action")], events
    assert monitor.engine.checks >= 10

    print(
        f"\nADS-B: first ADSB_VEHICLE {seen['first_report'] - t0:.2f} s wall after connecting "
        f"({seen['first_report'] - t_ready:.2f} s after SITL was ready), first conflict "
        f"{t_conflict - t0:.2f} s after connecting; {seen['reports']} reports from "
        f"{len(seen['keys'])} aircraft, altitudes {min(seen['alts']):.1f}-"
        f"{max(seen['alts']):.1f} m; {len(conflicts)} conflict event(s); first: {first}; "
        f"alert {text!r}"
    )
