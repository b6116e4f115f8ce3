"""Replay of a recorded telemetry trace: ArduPilot SITL (egham, speedup 5) flying north at
10 m/s into a 100 m keep-out square whose near edge is 150 m north of home, recorded by the
monitor itself (tests/test_monitor_flight_sitl.py with ALPHAFENCE_RECORD_TRACE). Times are
wall seconds of telemetry arrival; one wall second is five seconds of flight."""

import json
from pathlib import Path

import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Engine, Sample
from tests.sitl_flight import speedup_options

TRACE = Path(__file__).parent / "data" / "trace-egham-fence-x5.jsonl"
SPEEDUP = 5.0
FRAME = LocalFrame(-0.55, 51.43)  # the egham home


def fences():
    square = shapely.box(-50, 150, 50, 250)
    return FenceSet(
        [
            FenceRecord("test/square", "keep_out", FRAME.geom_to_wgs84(square)),
            FenceRecord("test/square-warning", "warning", FRAME.geom_to_wgs84(square.buffer(30.0))),
        ]
    )


def options(**kw):
    return speedup_options(SPEEDUP, **kw)


def samples():
    return [Sample(**json.loads(line)) for line in TRACE.read_text().splitlines()]


def north(s):
    return float(FRAME.to_local(s.lon, s.lat)[1])


def test_recorded_flight_warns_and_predicts_before_the_edge():
    trace = samples()
    eng = Engine(fences(), options())
    levels = {}
    for s in trace:
        for e in eng.step(s):
            if e["event"] == "level":
                levels.setdefault(e["level"], s)
    crossing = next(s for s in trace if north(s) >= 150.0)  # where the vehicle reached the fence
    assert levels["BREACH"].t >= crossing.t - 0.05
    for level, min_lead_s in (("WARNING", 10.0), ("IMMINENT", 3.0)):
        lead_flight = (crossing.t - levels[level].t) * SPEEDUP
        assert lead_flight >= min_lead_s, (level, lead_flight)
    assert not [
        e for s in trace for e in Engine(fences(), options()).step(s) if e["event"] == "gps_glitch"
    ]


def test_recorded_flight_with_enforce_commands_the_brake_first():
    eng = Engine(fences(), options(enforce=True))
    actions = [e for s in samples() for e in eng.step(s) if e["event"] == "action"]
    assert actions and actions[0]["action"] == "brake"


def test_a_trace_file_that_is_too_big_or_unreadable_is_one_line(tmp_path, monkeypatch):
    import pytest

    from alphafence.errors import InputError
    from alphafence.review import replay

    monkeypatch.setattr(replay, "MAX_TRACE_BYTES", 1000)
    big = tmp_path / "big.trace.jsonl"
    big.write_bytes(b"{}\n" * 400)
    with pytest.raises(InputError, match=r"big.trace.jsonl: a trace over 0 MB"):
        replay.Trace.read(big)
    with pytest.raises(InputError, match=r"missing.jsonl: cannot read \(No such file"):
        replay.Trace.read(tmp_path / "missing.jsonl")
