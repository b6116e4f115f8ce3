"""The decision engine on synthetic traces: alerts before breaches, actions only with
--enforce, pilot back-off, GPS glitches and stale telemetry as events, never crashes."""

import math

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.events import alert_text
from alphafence.monitor.options import MonitorOptions

FRAME = LocalFrame(-0.55, 51.43)


@pytest.fixture
def fences():
    square = shapely.box(-50, 200, 50, 300)
    return FenceSet(
        [
            FenceRecord("prison/way/1", "keep_out", FRAME.geom_to_wgs84(square)),
            FenceRecord(
                "prison/way/1",
                "warning",
                FRAME.geom_to_wgs84(square.buffer(30, join_style="mitre")),
            ),
        ]
    )


def north_run(speed=10.0, dt=0.1, seconds=30, mode="GUIDED"):
    for k in range(int(seconds / dt)):
        t = k * dt
        lon, lat = FRAME.to_wgs84(0.0, speed * t)
        yield Sample(t, float(lat), float(lon), 20.0, vn=speed, ve=0.0, mode=mode, armed=True)


def run(engine, samples):
    events = []
    for s in samples:
        events += engine.step(s)
    return events


def test_alert_mode_warns_early_and_never_acts(fences):
    events = run(Engine(fences, MonitorOptions(enforce=False)), north_run())
    levels = {e["level"]: e["time"] for e in events if e["event"] == "level"}
    assert levels["BREACH"] == pytest.approx(20.0, abs=0.11)
    assert levels["BREACH"] - levels["WARNING"] >= 3 and levels["BREACH"] - levels["IMMINENT"] >= 2
    assert not [e for e in events if e["event"] == "action"]
    warn = next(e for e in events if e["event"] == "level" and e["level"] == "WARNING")
    assert warn["fence"] == "prison/way/1" and warn["time_to_breach_s"] > 3
    assert alert_text(warn).startswith("AF WARNING prison/way/1") and len(alert_text(warn)) <= 50


def test_enforce_brakes_at_imminent_then_rtl_at_breach(fences):
    events = run(Engine(fences, MonitorOptions(enforce=True)), north_run())
    actions = [(e["time"], e["action"]) for e in events if e["event"] == "action"]
    assert [a for _, a in actions] == ["brake", "rtl"]
    assert actions[0][0] < 20.0 - 2.0


def test_pilot_mode_change_backs_off(fences):
    eng = Engine(fences, MonitorOptions(enforce=True, backoff_s=30))
    samples = list(north_run())
    for s in samples[150:]:
        s.mode = "POSHOLD"  # the pilot takes over (POSHOLD) at t = 15 s, then still flies on
    events = run(eng, samples)
    assert any(e["event"] == "pilot_mode_change" for e in events)
    assert not [e for e in events if e["event"] == "action" and e["time"] > 15]
    assert [e for e in events if e["event"] == "action_withheld"]


def test_the_first_mode_known_is_not_the_pilot_taking_over(fences):
    # the position stream can start before the flight-mode stream (seen on SITL): the mode
    # arriving with the second sample is where the vehicle already was, not a change
    eng = Engine(fences, MonitorOptions(enforce=True))
    samples = list(north_run(seconds=1))
    samples[0].mode = None
    for s in samples[1:]:
        s.mode = "STABILIZE"  # a pilot mode: a change into it would start the back-off
    events = run(eng, samples)
    assert not [e for e in events if e["event"] == "pilot_mode_change"]
    assert eng.backoff_until < 0


def test_gps_glitches_and_stale_telemetry_are_events(fences):
    eng = Engine(fences)
    s0 = Sample(0.0, 51.43, -0.55, 20.0)
    assert eng.step(s0) == []  # 200 m from the fence: clear, nothing to say
    assert eng.step(Sample(0.1, float("nan"), -0.55, 20.0))[0]["event"] == "gps_glitch"
    assert eng.step(Sample(0.2, 0.0, 0.0, 20.0))[0]["event"] == "gps_glitch"
    assert "jumped" in eng.step(Sample(0.3, 51.53, -0.55, 20.0))[0]["reason"]  # 11 km in 0.3 s
    assert eng.tick(0.5) == []
    stale = eng.tick(1.5)
    assert (
        stale[0]["event"] == "telemetry_stale" and stale[0]["age_s"] == 1.5 and eng.tick(1.6) == []
    )
    resumed = eng.step(Sample(1.7, 51.43, -0.55, 20.0))
    assert resumed[0]["event"] == "telemetry_resumed"
    assert eng.checks == 2  # glitches were never checked against the fences


def test_hovering_next_to_a_fence_does_not_flap(fences):
    eng = Engine(fences, MonitorOptions(hold_s=2.0))
    events = []
    for k in range(200):  # 20 s hovering 2-4 m in and out of the warning layer
        y = 170.0 + 2.0 * math.sin(k / 3.0)
        lon, lat = FRAME.to_wgs84(0.0, y)
        events += eng.step(Sample(k * 0.1, float(lat), float(lon), 20.0))
    assert len([e for e in events if e["event"] == "level"]) <= 2


def test_switching_into_guided_or_auto_is_not_the_pilot_taking_over(fences):
    eng = Engine(fences, MonitorOptions(enforce=True))
    samples = list(north_run(mode="BRAKE"))
    for s in samples[10:]:
        s.mode = "GUIDED"  # an autonomous mode, no back-off
    events = run(eng, samples)
    assert not [e for e in events if e["event"] in ("pilot_mode_change", "action_withheld")]
    assert [e["action"] for e in events if e["event"] == "action"] == ["brake", "rtl"]


def test_undoing_the_monitors_brake_backs_off(fences):
    eng = Engine(fences, MonitorOptions(enforce=True, backoff_s=60))
    events = []
    for s in north_run():
        if eng.action_t > -1 and s.t > eng.action_t + 0.5:
            s.mode = (
                "BRAKE" if s.t < eng.action_t + 1.5 else "GUIDED"
            )  # our brake, then the pilot resumes
        events += eng.step(s)
    assert [e for e in events if e["event"] == "pilot_mode_change"]
    assert [e["action"] for e in events if e["event"] == "action"] == ["brake"]


def test_arrival_jitter_is_not_a_glitch(fences):
    eng = Engine(fences)
    lon0, lat0 = FRAME.to_wgs84(0.0, 0.0)
    lon1, lat1 = FRAME.to_wgs84(0.0, 12.0)  # 12 m, but the two reports arrived 10 ms apart
    eng.step(Sample(0.0, float(lat0), float(lon0), 20.0))
    assert eng.step(Sample(0.01, float(lat1), float(lon1), 20.0)) == []


def test_failsafe_events_take_their_configured_actions(fences):
    opts = MonitorOptions(enforce=True, on_glitch="brake", on_stale="none", on_link_lost="land")
    eng = Engine(fences, opts)
    assert eng.step(Sample(0.0, 51.43, -0.55, 20.0)) == []
    glitch = eng.step(Sample(0.1, 0.0, 0.0, 20.0))
    assert [e["event"] for e in glitch] == ["gps_glitch", "action"] and glitch[1][
        "action"
    ] == "brake"
    assert [e["event"] for e in eng.tick(1.5)] == ["telemetry_stale"]  # on_stale = none
    lost = eng.tick(5.5)
    assert [e["event"] for e in lost] == ["link_lost", "action"] and lost[1]["action"] == "land"
    assert eng.tick(9.0) == []  # once
    # alerting only: the same events, no actions
    quiet = Engine(fences, MonitorOptions(on_glitch="brake", on_link_lost="land"))
    quiet.step(Sample(0.0, 51.43, -0.55, 20.0))
    assert [e["event"] for e in quiet.step(Sample(0.1, 0.0, 0.0, 20.0))] == ["gps_glitch"]


def test_losing_the_3d_fix_is_a_glitch_event_once(fences):
    eng = Engine(fences, MonitorOptions(enforce=True, on_glitch="land"))
    assert eng.step(Sample(0.0, 51.43, -0.55, 20.0, gps_fix=3)) == []
    degraded = eng.step(Sample(0.1, 51.43, -0.55, 20.0, gps_fix=1))
    assert [e["event"] for e in degraded] == ["gps_glitch", "action"] and "fix type 1" in degraded[
        0
    ]["reason"]
    assert eng.step(Sample(0.2, 51.43, -0.55, 20.0, gps_fix=0)) == []  # once
    assert eng.step(Sample(0.3, 51.43, -0.55, 20.0, gps_fix=4)) == []  # back to normal
    assert eng.checks == 2
