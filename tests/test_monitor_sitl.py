"""The async monitor against real ArduPilot SITL."""

import asyncio
import json

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor import run, runner
from alphafence.monitor.options import MonitorOptions
from tests.helpers import until

pytestmark = pytest.mark.sitl
EGHAM = (-0.55, 51.43)


@pytest.mark.parametrize("sitl", [{"home": "egham", "speedup": 1}], indirect=True)
async def test_monitor_sees_a_vehicle_parked_in_a_keep_out_zone(sitl, tmp_path, monkeypatch):
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
    stop = asyncio.Event()
    made, at_breach = [], []  # the monitor run_monitor makes; its checks at the BREACH

    class Counted(runner.Monitor):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(run, "Monitor", Counted)

    def echo(event):
        if event["event"] == "level" and event["level"] == "BREACH":
            at_breach.append(made[0].engine.checks)

    options = MonitorOptions(enforce=False, mavlink_traffic=True)
    task = asyncio.create_task(
        run.run_monitor(sitl.connection_url, fences, options, log, stop, echo=echo)
    )
    # however long connecting takes on a busy host; then positions go on being checked at the
    # telemetry rate: ten more after the breach
    await until(lambda: at_breach or task.done(), "the monitor's BREACH", 60)
    assert not task.done(), task
    await until(
        lambda: made[0].engine.checks >= at_breach[0] + 10 or task.done(),
        "ten position checks after the breach",
        60,
    )
    assert not task.done(), task
    stop.set()
    monitor = await asyncio.wait_for(task, 10)
    assert monitor is made[0]
    events = [json.loads(line) for line in log.read_text().splitlines()]
    breach = [e for e in events if e["event"] == "level" and e["level"] == "BREACH"]
    assert breach and breach[0]["fence"] == "test/around-home"
    assert abs(breach[0]["lat"] - EGHAM[1]) < 1e-3 and abs(breach[0]["lon"] - EGHAM[0]) < 1e-3
    assert not [e for e in events if e["event"] in ("action", "alert_failed")]
    # the vehicle's own GLOBAL_POSITION_INT is not traffic; there is no other aircraft here
    assert not [e for e in events if e["event"].startswith("traffic")], events
    assert monitor.engine.traffic.aircraft == {}
