"""Events carry UTC (ISO 8601, milliseconds) beside their monotonic time: on this computer's
clock live, on the replayed flight's clock in a replay, and the event log's first line says
which."""

from __future__ import annotations

import io
import json
import time

import pytest

from alphafence.cli.demo import trace_path
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import UtcClock, new_event, utc_seconds
from alphafence.review.replay import Trace, replay, speedup_options

from .helpers import until


def test_an_event_is_stamped_in_utc_on_this_computers_clock():
    t = time.monotonic() - 100.0  # a hundred seconds ago
    before = time.time()
    e = new_event("action", t, action="brake")
    after = time.time()
    assert list(e)[:3] == ["time", "utc", "event"] and e["utc"].endswith("Z")
    assert before - 100.002 <= utc_seconds(e["utc"]) <= after - 99.998


async def test_the_event_log_says_where_its_utc_comes_from(tmp_path):
    path = tmp_path / "events.jsonl"
    seen = []
    log = EventLog(path, echo=seen.append, clock=UtcClock.wall())
    log.put(new_event("level", level="WARNING"))
    await until(lambda: path.exists() and len(path.read_text().splitlines()) == 2, "two lines")
    await log.close()
    header, event = (json.loads(line) for line in path.read_text().splitlines())
    assert header["event"] == "clock" and header["utc_source"] == "wall clock"
    assert event["event"] == "level" and event["utc"].endswith("Z")
    assert [e["event"] for e in seen] == ["level"] and list(log.events) == seen  # file only


def demo_trace(clock=None) -> Trace:
    trace = Trace.read(trace_path())
    trace.clock = clock
    return trace


def test_a_replay_takes_utc_from_the_trace_when_it_has_a_clock(tmp_path):
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.cli import main

    fences = tmp_path / "fences.geojson"
    from alphafence.cli.demo import scene_path

    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    trace = demo_trace()
    t0 = trace.samples[0].t
    trace.clock = {"t": t0, "utc": "2026-11-30T10:00:00.000Z", "source": "wall clock"}
    again = Trace.from_text(trace.to_text())  # the clock is kept in the header
    assert again.clock == trace.clock
    clock = again.utc_clock()
    assert clock.source == "trace (wall clock)"
    events = replay(again, FenceSet.from_geojson(fences), speedup_options(again.speedup))
    start = utc_seconds("2026-11-30T10:00:00.000Z")
    for e in events:
        assert abs(utc_seconds(e["utc"]) - (start + e["time"] - t0)) < 0.0015, e
    assert events[0]["utc"].startswith("2026-11-30T10:00:")
    # without a clock in the trace: the wall clock, the first sample now
    wall = demo_trace().utc_clock()
    assert wall.source == "wall clock"
    assert abs(utc_seconds(wall.utc(t0)) - time.time()) < 60.0


def test_a_bad_clock_in_a_trace_is_one_line(tmp_path):
    text = trace_path().read_text().splitlines()
    header = json.loads(text[0])
    header["clock"] = {"t": 1.0, "utc": "yesterday"}
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join([json.dumps(header), *text[1:]]) + "\n")
    from alphafence.errors import InputError

    with pytest.raises(InputError) as exc:
        Trace.read(bad)
    assert str(bad) in str(exc.value) and "malformed clock" in str(exc.value)


def test_the_monitor_prints_each_event_with_its_utc(monkeypatch):
    from alphafence.cli import common
    from alphafence.cli import monitor as cli_monitor

    buf = io.StringIO()
    monkeypatch.setattr(common.out_console, "_file", buf)
    e = new_event("level", 12.5, level="WARNING", previous="CLEAR", reason="predicted")
    cli_monitor._echo(e)
    assert buf.getvalue().startswith(f"{e['utc']} 12.5 CLEAR -> WARNING")
