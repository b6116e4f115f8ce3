"""``alphafence sitl --fly``: a mission file's items as a ground station uploads them, and a
vehicle that is not simulated is never armed. (The flight itself is flown on real SITL by the
getting-started walkthrough, tests/test_docs_walkthrough.py.)"""

from __future__ import annotations

import asyncio
import json

import pytest

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.flights.mission_items import mission_rows
from alphafence.mavlink import ids
from alphafence.sitl.fly import NotSimulated, fly_mission, raw_items
from alphafence.vehicle.link import open_vehicle
from tests.fake_vehicle import FakeVehicle

# a route's mission as 'alphafence route' writes it (Malta, lat/lon)
PATH = [(14.50, 35.90), (14.505, 35.905), (14.51, 35.903)]


@pytest.fixture
def route_files(tmp_path):
    from alphafence.fencefiles.qgc_plan import mission_items

    items = mission_items(__import__("numpy").array(PATH), 30.0)
    plan = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "AlphaFence",
        "mission": {
            "version": 2,
            "firmwareType": 3,
            "vehicleType": 2,
            "cruiseSpeed": 10,
            "hoverSpeed": 5,
            "plannedHomePosition": [PATH[0][1], PATH[0][0], 20.0],
            "items": items,
        },
        "geoFence": {"version": 2, "polygons": [], "circles": []},
        "rallyPoints": {"version": 2, "points": []},
    }
    path = tmp_path / "route.plan"
    path.write_text(json.dumps(plan))
    return path, items


def test_a_plans_items_are_uploaded_as_written_home_first(route_files):
    path, items = route_files
    rows = mission_rows(path)
    assert len(rows) == len(items) + 1 and [r.seq for r in rows] == list(range(len(rows)))
    home = rows[0]
    assert (home.lat, home.lon, home.alt) == (PATH[0][1], PATH[0][0], 20.0)
    for row, it in zip(rows[1:], items):
        assert row.command == it["command"] and row.frame == it["frame"]
        p = it["params"]
        if p[4] is not None:
            assert (row.lat, row.lon, row.alt) == (p[4], p[5], p[6])
    raw = raw_items(rows)
    assert [r.current for r in raw][:3] == [0, 1, 0]
    assert all(r.mission_type == ids.MAV_MISSION_TYPE_MISSION for r in raw)
    assert raw[2].x == round(rows[2].lat * 1e7) and raw[2].y == round(rows[2].lon * 1e7)


def test_a_waypoint_file_reads_as_the_same_items(route_files, tmp_path):
    path, _ = route_files
    rows = mission_rows(path)
    lines = ["QGC WPL 110"]
    for r in rows:
        p = "\t".join(f"{v:.8f}" for v in (*r.params, r.lat, r.lon, r.alt))
        lines.append(f"{r.seq}\t{int(r.seq == 0)}\t{r.frame}\t{r.command}\t{p}\t1")
    wpl = tmp_path / "route.waypoints"
    wpl.write_text("\n".join(lines) + "\n")
    again = mission_rows(wpl)
    assert [(r.command, r.frame) for r in again] == [(r.command, r.frame) for r in rows]
    assert [round(r.lat, 7) for r in again] == [round(r.lat, 7) for r in rows]


def test_a_complex_item_is_refused_in_one_line(route_files, tmp_path):
    path, _ = route_files
    doc = json.loads(path.read_text())
    doc["mission"]["items"].insert(1, {"type": "ComplexItem", "complexItemType": "survey"})
    bad = tmp_path / "survey.plan"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"item 2: complex item 'survey'"):
        mission_rows(bad)


async def test_a_vehicle_without_sim_parameters_is_never_flown(route_files):
    path, _ = route_files
    async with FakeVehicle() as fake:  # a real vehicle, as far as its parameters tell
        async with open_vehicle(fake.url, 10, link="pymavlink") as vehicle:
            with pytest.raises(NotSimulated, match="SIM_SPEEDUP parameter"):
                await fly_mission(vehicle, mission_rows(path), say=lambda _: None)
        assert fake.received("PARAM_REQUEST_READ")
        for nothing in ("MISSION_COUNT", "COMMAND_LONG"):
            assert not fake.received(nothing), nothing


def test_fly_needs_a_connection(route_files, capsys):
    path, _ = route_files
    assert main(["sitl", "--fly", str(path)]) == 2
    assert "--fly: needs --connect" in capsys.readouterr().err
    assert main(["sitl", "--home", "0,0,0,0", "--serial1", "/tmp/x"]) == 2
    assert "expected uart:PATH:BAUD" in capsys.readouterr().err


def test_the_flight_follows_the_armed_state():
    from alphafence.sitl.fly import _Armed

    armed = _Armed()

    class V:
        class telemetry:
            @staticmethod
            async def subscribe_armed():
                for a in (False, True, True, False):
                    yield a

    asyncio.run(armed.follow(V))
    assert armed.was_armed and armed.done.is_set()


@pytest.mark.sitl
def test_sitl_run_by_hand_stops_its_simulator_on_sigterm_and_ctrl_c(sitl_binary):
    """``alphafence sitl --home`` stopped by SIGTERM (a service manager, ``kill``) or by
    Ctrl-C when started with ``&`` (SIGINT ignored) takes its arducopter with it."""
    import os
    import signal
    import subprocess
    import sys

    for sig, ignore_sigint in ((signal.SIGTERM, False), (signal.SIGINT, True)):
        proc = subprocess.Popen(
            [sys.executable, "-m", "alphafence", "sitl", "--home", "egham", "--no-wait"],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            preexec_fn=(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
            if ignore_sigint
            else None,
        )
        pid = None
        for line in proc.stdout:
            if line.startswith("SITL "):
                pid = int(line.split("pid")[1].split()[0])
            if "Ctrl-C stops SITL" in line:
                break
        assert pid is not None
        proc.send_signal(sig)
        rest = proc.stdout.read()
        assert proc.wait(timeout=60) == 0, rest
        assert "stopped" in rest
        try:
            os.kill(pid, 0)
            alive = not open(f"/proc/{pid}/stat").read().split()[2] == "Z"
        except (ProcessLookupError, FileNotFoundError):
            alive = False
        assert not alive, f"arducopter {pid} still runs after {sig.name}"
