"""The async monitor against real ArduPilot SITL."""

import asyncio
import json

import pytest
import shapely

from alphafence.formats.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.fenceset import FenceSet
from alphafence.monitor.options import MonitorOptions
from alphafence.monitor.runner import run_monitor

pytestmark = pytest.mark.sitl
EGHAM = (-0.55, 51.43)


@pytest.mark.parametrize("sitl", [{"home": "egham", "speedup": 1}], indirect=True)
async def test_monitor_sees_a_vehicle_parked_in_a_keep_out_zone(sitl, tmp_path):
    frame = LocalFrame(*EGHAM)
    fences = FenceSet(
        [
            FenceRecord(
                "test/around-home", "keep_out", frame.geom_to_wgs84(shapely.box(-50, -50, 50, 50))
            ),
            FenceRecord(
                "test/far", "keep_out", frame.geom_to_wgs84(shapely.box(1000, 1000, 1100, 1100))
            ),
        ]
    )
    log = tmp_path / "events.jsonl"
    stop, breached = asyncio.Event(), asyncio.Event()

    def echo(event):
        if event["event"] == "level" and event["level"] == "BREACH":
            breached.set()

    options = MonitorOptions(enforce=False, mavlink_traffic=True)
    task = asyncio.create_task(
        run_monitor(sitl.connection_url, fences, options, log, stop, echo=echo)
    )
    await asyncio.wait_for(breached.wait(), 60)  # however long connecting takes on a busy host
    await asyncio.sleep(3.0)  # then 3 s of SITL's real-time telemetry (speedup 1)
    stop.set()
    monitor = await asyncio.wait_for(task, 10)
    events = [json.loads(line) for line in log.read_text().splitlines()]
    breach = [e for e in events if e["event"] == "level" and e["level"] == "BREACH"]
    assert breach and breach[0]["fence"] == "test/around-home"
    assert abs(breach[0]["lat"] - EGHAM[1]) < 1e-3 and abs(breach[0]["lon"] - EGHAM[0]) < 1e-3
    # position checks run at the telemetry rate (>= 5 Hz: some 15 in the 3 s after the breach)
    assert monitor.engine.checks >= 10
    assert not [e for e in events if e["event"] in ("action", "alert_failed")]
    # the vehicle's own GLOBAL_POSITION_INT is not traffic; there is no other aircraft here
    assert not [e for e in events if e["event"].startswith("traffic")], events
    assert monitor.engine.traffic.aircraft == {}
