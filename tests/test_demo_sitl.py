"""``alphafence demo`` with ArduPilot SITL (``make demo`` when a binary is found): the demo
scene's fences are built, compiled into a copter's 560 bytes, uploaded and verified, and the
copter is flown in GUIDED at 10 m/s toward the nearest keep-out fence with the enforcing
monitor running (its onboard layer on). The monitor warns, raises IMMINENT and brakes; the
copter stops outside every full-resolution and every onboard fence. About 20 s wall (SITL at
speedup 5, its start included)."""

import io
import json

import numpy as np
import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.demo import HOME
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.geo.frame import LocalFrame
from alphafence.review.replay import Trace
from tests.test_demo import PNG, keep_out_shapes

pytestmark = pytest.mark.sitl


def test_the_demo_flies_at_a_fence_and_stops_outside_it(sitl_binary, tmp_path, monkeypatch):
    from alphafence.cli import common

    buf = io.StringIO()
    monkeypatch.setenv("ARDUPILOT_SITL", str(sitl_binary))
    monkeypatch.setattr(common.out_console, "_file", buf)
    assert main(["demo", "-o", str(tmp_path)]) == 0
    printed = buf.getvalue()
    assert "replay" not in printed.lower(), printed
    assert "uploaded" in printed and "verified" in printed, printed

    assert (tmp_path / "flight.png").read_bytes()[:8] == PNG
    events = [json.loads(line) for line in (tmp_path / "events.jsonl").read_text().splitlines()]
    assert not [e for e in events if e.get("replay")]
    compiled = read_plan_fence(tmp_path / "onboard.plan")
    loaded = next(e for e in events if e["event"] == "onboard_fence")
    assert loaded["items"] == len(compiled) and loaded["cause"] == "start", loaded
    levels = [e["level"] for e in events if e["event"] == "level"]
    assert "IMMINENT" in levels or "WARNING" in levels, events
    assert "BREACH" not in levels, events
    actions = [e for e in events if e["event"] == "action"]
    assert actions and actions[0]["action"] == "brake", events
    assert not [e for e in events if e["event"] in ("action_failed", "onboard_failed")], events

    # the flight, as the monitor saw it: at the fence, and outside every fence all the way
    trace = Trace.read(tmp_path / "flight.trace.jsonl")
    assert trace.onboard_items == compiled
    frame = LocalFrame(*HOME)
    full, onboard = keep_out_shapes(tmp_path / "fences.geojson", compiled, frame)
    xy = np.array([frame.to_local(s.lon, s.lat) for s in trace.samples], dtype=float)
    track = shapely.points(xy)[:, None]
    gap_full = float(shapely.distance(track, np.array(full)[None, :]).min())
    gap_onboard = float(shapely.distance(track, np.array(onboard)[None, :]).min())
    assert gap_full > 0 and gap_onboard > 0, (gap_full, gap_onboard)
    assert float(np.hypot(*xy.T).max()) > 150.0  # it flew toward the fence
    last = trace.samples[-1]
    assert np.hypot(last.vn, last.ve) < 0.5  # and stopped there
    print(
        f"\ndemo flight: {len(trace.samples)} positions, levels {levels}, closest to a "
        f"full-resolution fence {gap_full:.1f} m, to an onboard fence {gap_onboard:.1f} m"
    )


def test_sigterm_during_the_flight_stops_sitl_and_writes_no_flight(sitl_binary, tmp_path):
    import os
    import signal
    import subprocess
    import sys

    exe = os.path.join(os.path.dirname(sys.executable), "alphafence")
    env = {**os.environ, "ARDUPILOT_SITL": str(sitl_binary)}
    demo = subprocess.Popen(
        [exe, "demo", "-o", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    try:
        for line in demo.stdout:  # each line as it is printed
            if line.startswith("armed"):
                break
        children = subprocess.run(
            ["pgrep", "-P", str(demo.pid)], capture_output=True, text=True
        ).stdout.split()
        sitl = [pid for pid in children if "arducopter" in _cmdline(pid)]
        assert sitl, children
        demo.send_signal(signal.SIGTERM)
        rest = demo.stdout.read()
        assert demo.wait(timeout=30) == 143, rest
    finally:
        if demo.poll() is None:
            demo.kill()
    assert "SITL stopped" in rest
    assert not [pid for pid in sitl if os.path.exists(f"/proc/{pid}")], sitl
    assert (tmp_path / "fences.geojson").is_file() and not (tmp_path / "events.jsonl").exists()


def _cmdline(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().decode(errors="replace")
    except OSError:
        return ""
