"""The monitor's event log: written off the event loop, and a log that cannot be written never
stops, hangs or grows the monitor (found by the soak bench: a failed write used to end the
writer silently, queue every later event and make close() wait forever)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from alphafence.cli import main
from alphafence.monitor.eventlog import EventLog

from .helpers import until

DEMO_SCENE = (
    Path(__file__).resolve().parents[1] / "kit" / "alphafence" / "data" / "demo-scene.geojson"
)


async def test_events_are_appended_as_json_lines(tmp_path):
    path = tmp_path / "events.jsonl"
    log = EventLog(path)
    for i in range(50):
        log.put({"time": i, "event": "level", "level": "CLEAR"})
    await log.close()
    lines = path.read_text().splitlines()
    assert [json.loads(line)["time"] for line in lines] == list(range(50))
    assert log.lost == 0


async def test_a_failing_log_is_reported_once_and_close_returns(tmp_path):
    folder = tmp_path / "gone"
    folder.mkdir()
    seen = []
    path = folder / "events.jsonl"
    log = EventLog(path, echo=seen.append)
    log.put({"time": 0, "event": "level"})
    await until(lambda: path.exists() and path.read_text().endswith("\n"), "the first line written")
    path.unlink()
    folder.rmdir()  # the directory is gone: every later append fails
    for batch in range(10):  # ten writes that fail, each waited for (counted as lost)
        for i in range(100 * batch + 1, 100 * batch + 101):
            log.put({"time": i, "event": "level"})
        await until(lambda n=100 * batch + 100: log.lost >= n, f"{100 * batch + 100} lines lost")
    # what came after the failure is counted, not kept: the 1000 lines and the failure's own
    await until(lambda: log.lost == 1001, "the failure's own line lost too")
    assert not log.task.done() and log.queue.qsize() == 0  # the writer went on
    await asyncio.wait_for(log.close(), 30)  # the old writer made this wait forever
    failures = [e for e in seen if e["event"] == "log_write_failed"]
    assert len(failures) == 1 and "events.jsonl" in failures[0]["error"]
    assert log.lost == 1001


async def test_memory_holds_only_the_latest_events():
    log = EventLog(None, keep=100)
    for i in range(1000):
        log.put({"time": i, "event": "level"})
    assert len(log.events) == 100 and log.events[0]["time"] == 900
    await log.close()


def test_cli_refuses_an_unwritable_log_before_connecting(tmp_path, capsys):
    fences = tmp_path / "f.geojson"
    assert main(["build", str(DEMO_SCENE), "-o", str(fences)]) == 0
    bad = tmp_path / "no-such-dir" / "events.jsonl"
    code = main(
        ["monitor", "--allow-unsigned", "--connect", "udpin://127.0.0.1:9",
         "--fences", str(fences), "--log", str(bad)]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "cannot write the event log" in err and str(bad) in err
    assert len([line for line in err.splitlines() if "error" in line]) == 1


class _Telemetry:
    """Positions at 50 Hz; the armed stream breaks after one value; the rest stay silent."""

    async def set_rate_position(self, hz):
        pass

    async def set_rate_velocity_ned(self, hz):
        pass

    async def subscribe_position(self):
        from types import SimpleNamespace

        while True:
            await asyncio.sleep(0.02)
            yield SimpleNamespace(
                latitude_deg=35.95, longitude_deg=14.45, relative_altitude_m=20.0,
                absolute_altitude_m=60.0,
            )  # fmt: skip

    async def subscribe_armed(self):
        yield True
        raise RuntimeError("stream broke")

    async def _silent(self):
        await asyncio.Event().wait()
        yield None

    subscribe_velocity_ned = subscribe_flight_mode = subscribe_gps_info = _silent


async def test_a_telemetry_stream_that_ends_is_an_event_once_and_checks_go_on():
    from types import SimpleNamespace

    import shapely

    from alphafence.awareness.fenceset import FenceSet
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor

    fences = FenceSet([FenceRecord("sq", "keep_out", shapely.box(14.50, 35.90, 14.51, 35.91))])
    vehicle = SimpleNamespace(telemetry=_Telemetry(), system=None)
    log = EventLog(None)
    monitor = Monitor(vehicle, fences, MonitorOptions(), log)
    monitor.feeds.pop("adsb")  # no MAVSDK system behind the stub: no ADS-B
    stop = asyncio.Event()
    task = asyncio.create_task(monitor.run(stop))
    # 50 positions a second: wait until the broken stream is reported and 100 positions came
    # after it (2 s at the stub's rate, longer on a busy host), so that a repeat would show

    def running(condition):
        assert not task.done(), log.events
        return condition()

    await until(
        lambda: running(lambda: [e for e in log.events if e["event"] == "telemetry_task_ended"]),
        "the broken stream reported",
    )
    ended_at = monitor.engine.checks
    await until(
        lambda: running(lambda: monitor.engine.checks >= ended_at + 100),
        "100 positions checked after it",
    )
    stop.set()
    await asyncio.wait_for(task, 5)
    ended = [e for e in log.events if e["event"] == "telemetry_task_ended"]
    assert len(ended) == 1, ended
    assert ended[0]["task"] == "telemetry:armed" and "stream broke" in ended[0]["error"]
    assert monitor.engine.checks > 20  # the monitor kept checking positions


async def test_a_live_source_polling_that_ends_is_an_event_and_an_alert():
    """The polling outlives anything a server sends (tests/test_hostile_source.py); were it to
    end all the same (a fault of the kit's own, made here), the monitor says so and goes on."""
    from types import SimpleNamespace

    import shapely

    from alphafence.awareness.fenceset import FenceSet
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.fencing.pipeline import BuildOptions
    from alphafence.monitor.events import alert_text
    from alphafence.monitor.live import LiveOptions
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.sources.ogc import SourceOptions

    fences = FenceSet([FenceRecord("sq", "keep_out", shapely.box(14.50, 35.90, 14.51, 35.91))])
    vehicle = SimpleNamespace(telemetry=_Telemetry(), system=None)
    log = EventLog(None)
    live = LiveOptions(SourceOptions("http://127.0.0.1:9/collections/z"), None, BuildOptions())
    monitor = Monitor(vehicle, fences, MonitorOptions(), log, live=live)
    monitor.feeds.pop("adsb")
    monitor.commands.alert = _no_alert

    async def broken(stop):
        raise RuntimeError("a fault of the kit's own")

    monitor.live.run = broken
    stop = asyncio.Event()
    task = asyncio.create_task(monitor.run(stop))
    await until(lambda: [e for e in log.events if e["event"] == "source_ended"] or task.done(),
                "the ended polling reported")  # fmt: skip
    assert not task.done()
    checks = monitor.engine.checks
    await until(lambda: monitor.engine.checks > checks + 10, "positions checked after it")
    stop.set()
    await asyncio.wait_for(task, 5)
    (ended,) = [e for e in log.events if e["event"] == "source_ended"]
    assert "a fault of the kit's own" in ended["error"]
    assert alert_text(ended) == "AF ZONE SOURCE ENDED: zones kept, none new"


async def _no_alert(text, event=None):
    return None
