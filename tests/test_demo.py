"""``alphafence demo`` without SITL: the build as before, then the demo flight recorded from
ArduPilot SITL (shipped as package data) replayed through the monitor, labelled as a replay.
The recorded trace itself is checked: its track stays outside every full-resolution and every
onboard keep-out fence, and replayed it warns, predicts and brakes before the fence."""

import io
import json

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.cli import main
from alphafence.cli.demo import HOME, trace_path
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Sample
from alphafence.monitor.events import utc_seconds
from alphafence.monitor.onboard import OnboardLayer
from alphafence.review.demo_flight import CLEAR_M, plan_leg
from alphafence.review.replay import Trace, replay, speedup_options

PNG = b"\x89PNG\r\n\x1a\n"
BUILD_OUTPUTS = ("fences.geojson", "fences.plan", "fences.waypoints", "fences.png", "compare.png")


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """The demo run with --replay (as without a SITL binary): its folder and what it printed."""
    out = tmp_path_factory.mktemp("demo")
    from alphafence.cli import common

    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(common.out_console, "_file", buf)  # rich's console, not sys.stdout
        assert main(["demo", "-o", str(out), "--replay"]) == 0
    return out, buf.getvalue()


def keep_out_shapes(fences_path, items, frame):
    """The full-resolution keep-out fences and the onboard exclusions, in ``frame``'s metres."""
    records = [r for r in read_fences(fences_path) if r.kind == "keep_out"]
    full = list(frame.geom_to_local(np.array([r.geometry for r in records], dtype=object)))
    layer = OnboardLayer.from_items(items, frame)
    onboard = [g for g, r in zip(layer.index.local, layer.index.records) if r.kind == "keep_out"]
    return full, onboard


def test_the_demo_without_sitl_builds_and_replays_the_recorded_flight(replayed):
    out, printed = replayed
    for name in BUILD_OUTPUTS + ("onboard.plan", "flight.trace.jsonl"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "flight.png").read_bytes()[:8] == PNG
    assert "replay" in printed.lower() and "recorded from ArduPilot SITL" in printed
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    assert events and all(e["replay"] is True for e in events)
    levels = [e["level"] for e in events if e["event"] == "level"]
    assert levels[:2] == ["WARNING", "IMMINENT"], levels
    assert "BREACH" not in levels
    loaded = next(e for e in events if e["event"] == "onboard_fence")
    assert loaded["items"] == len(Trace.read(trace_path()).onboard_items)
    actions = [e for e in events if e["event"] == "action"]
    assert actions and actions[0]["action"] == "brake"


def test_without_a_sitl_binary_the_demo_says_so_in_one_line_and_replays(
    tmp_path, capsys, monkeypatch
):
    from alphafence.sitl import find

    monkeypatch.setattr(find, "find_sitl_binary", lambda: None)
    assert main(["demo", "-o", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    said = [line for line in printed.splitlines() if "no ArduPilot SITL binary found" in line]
    assert len(said) == 1 and "replaying" in said[0], printed
    assert (tmp_path / "flight.png").read_bytes()[:8] == PNG
    assert "IMMINENT" in (tmp_path / "events.jsonl").read_text()


def test_the_recorded_flight_stays_outside_every_fence(replayed):
    out, _ = replayed
    trace = Trace.read(trace_path())
    assert "recorded from ArduPilot SITL" in trace.recorded and trace.speedup > 1
    frame = LocalFrame(*HOME)
    full, onboard = keep_out_shapes(out / "fences.geojson", trace.onboard_items, frame)
    xy = np.array([frame.to_local(s.lon, s.lat) for s in trace.samples], dtype=float)
    track = shapely.points(xy)
    assert len(trace.samples) > 100
    assert float(shapely.distance(track[:, None], np.array(full)[None, :]).min()) > 5.0
    assert float(shapely.distance(track[:, None], np.array(onboard)[None, :]).min()) > 5.0
    # it flew at the fence: the farthest point is well away from home, toward it
    assert float(np.hypot(*xy.T).max()) > 200.0


def test_the_replay_is_the_engine_on_the_trace(replayed):
    out, _ = replayed
    trace = Trace.read(trace_path())
    fences = FenceSet.from_geojson(out / "fences.geojson")
    options = speedup_options(trace.speedup, enforce=True)
    written = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    header, written = written[0], written[1:]
    assert header["event"] == "clock" and header["utc_source"] == "wall clock"
    events = replay(trace, fences, options)
    assert [{**e, "utc": None, "replay": True} for e in events] == [
        {**e, "utc": None} for e in written
    ]
    # every event's UTC is its monotonic time on the clock the header names (to the ms)
    offset = utc_seconds(header["utc"]) - header["time"]
    assert all(abs(utc_seconds(e["utc"]) - e["time"] - offset) < 0.0015 for e in written)
    # without the onboard layer the vehicle's fence is not loaded, the fences still warn
    off = replay(trace, fences, speedup_options(trace.speedup, onboard="off"))
    assert not [e for e in off if e["event"].startswith("onboard")]
    assert [e["level"] for e in off if e["event"] == "level"][:2] == ["WARNING", "IMMINENT"]


def test_a_trace_round_trips_and_a_bad_one_is_one_line(tmp_path):
    trace = Trace.read(trace_path())
    again = Trace.from_text(trace.to_text())
    assert again.to_text() == trace.to_text()
    assert again.onboard_items == trace.onboard_items
    assert isinstance(again.samples[0], Sample)
    for text, fault in (
        ("", "empty trace"),
        ('{"x": 1}\n', "not an AlphaFence trace"),
        ('{"trace": "alphafence-trace-1"}\n{"t": 1\n', "line 2: not JSON"),
        ('{"trace": "alphafence-trace-1"}\n{"t": 1, "colour": 2}\n', "malformed sample"),
    ):
        bad = tmp_path / "bad.jsonl"
        bad.write_text(text)
        with pytest.raises(InputError) as exc:
            Trace.read(bad)
        message = str(exc.value)
        assert str(bad) in message and fault in message and "\n" not in message


def test_the_leg_heads_for_the_nearest_keep_out_fence_to_a_clear_target(replayed):
    out, _ = replayed
    records = read_fences(out / "fences.geojson")
    items = Trace.read(trace_path()).onboard_items
    leg = plan_leg(records, items, HOME)
    frame = LocalFrame(*HOME)
    full, onboard = keep_out_shapes(out / "fences.geojson", items, frame)
    origin = shapely.Point(0, 0)
    assert leg.distance_m == pytest.approx(min(origin.distance(g) for g in full))
    target = shapely.Point(*frame.to_local(*leg.target))
    assert min(target.distance(g) for g in full + onboard) >= CLEAR_M
    # the straight line to the target crosses the nearest fence: the flight is at it
    line = shapely.LineString([(0, 0), target.coords[0]])
    assert any(line.intersects(g) for g in full)


def test_check_flight_reads_the_demos_tlog_and_finds_its_alerts(replayed, capsys):
    out, printed = replayed
    tlog = out / "flight.tlog"
    assert f"alphafence check-flight {tlog} --fences {out / 'fences.geojson'}" in printed
    capsys.readouterr()
    code = main(["check-flight", str(tlog), "--fences", str(out / "fences.geojson"), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and not report["entered"]  # it braked before the keep-out fence
    trace = Trace.read(trace_path())
    assert report["log"]["positions"] == len(trace.samples) and report["log"]["clock"] == "utc"
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    # the log's alerts are the replay's, at the same UTC (to the millisecond)
    replayed_alerts = [
        e for e in events if e["event"] == "level" and e["level"] in ("WARNING", "IMMINENT")
    ][:2]
    found = report["alerts"][:2]
    assert [a["level"] for a in found] == [e["level"] for e in replayed_alerts]
    assert [a["fence"] for a in found] == [e["fence"] for e in replayed_alerts]
    for a, e in zip(found, replayed_alerts):
        assert abs(utc_seconds(a["utc"]) - utc_seconds(e["utc"])) <= 0.002, (a, e)


def test_the_demos_tlog_holds_heartbeats_with_the_flights_modes(replayed):
    from pymavlink import mavutil

    out, _ = replayed
    log = mavutil.mavlogfile(str(out / "flight.tlog"))
    modes = []
    while (m := log.recv_match(type="HEARTBEAT")) is not None:
        name = mavutil.mode_string_v10(m)
        if not modes or modes[-1] != name:
            modes.append(name)
    log.close()
    assert modes == ["GUIDED", "BRAKE"]  # flown in GUIDED, stopped by the monitor's brake
