"""The monitor's pure parts: fence index queries, prediction arithmetic, alert levels."""

import math

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import (
    Braking,
    closest_approach,
    dynamic_radius,
    stopping_distance,
    time_to_breach,
)
from alphafence.awareness.state import Level, StateMachine, assess
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame

FRAME = LocalFrame(-0.55, 51.43)


def rec(site, kind, poly, alt_min=None, alt_max=None):
    return FenceRecord(site, kind, FRAME.geom_to_wgs84(poly), alt_min_m=alt_min, alt_max_m=alt_max)


@pytest.fixture
def fences():
    square = shapely.box(0, 200, 100, 300)  # keep-out, 200 m north of the origin
    return FenceSet(
        [
            rec("ko", "keep_out", square),
            rec("warn", "warning", square.buffer(30, join_style="mitre")),
            rec("high", "keep_out", shapely.box(-300, -50, -200, 50), alt_min=50, alt_max=120),
            rec("area", "keep_in", shapely.box(-1000, -1000, 1000, 1000)),
        ],
        frame=FRAME,
    )


def test_inside_nearest_and_ahead(fences):
    c = fences.check(50, 0, alt=20, vx=0, vy=10, lookahead_m=500)
    assert c.inside_keep_out == [] and c.outside_keep_in == []
    assert c.nearest_keep_out.index == 0 and c.nearest_keep_out.distance_m == pytest.approx(
        200, abs=0.01
    )
    assert c.breach_ahead[0] == 0 and c.breach_ahead[1] == pytest.approx(200, abs=0.01)
    inside = fences.check(50, 250, alt=20)
    assert inside.inside_keep_out == [0] and inside.inside_warning == [1]
    # altitude limits: inside the footprint of "high" but below it
    assert fences.check(-250, 0, alt=20).inside_keep_out == []
    assert fences.check(-250, 0, alt=80).inside_keep_out == [2]
    assert fences.check(1500, 0, alt=20).outside_keep_in == [3]
    # flying away: nothing ahead
    assert fences.check(50, 0, vx=0, vy=-10, lookahead_m=500).breach_ahead is None


def test_prediction_arithmetic():
    b = Braking(reaction_s=1.0, decel_mps2=2.5, margin_m=2.0)
    assert stopping_distance(10, b) == pytest.approx(10 + 100 / 5 + 2)
    assert stopping_distance(0, b) == pytest.approx(2.0)
    assert time_to_breach(200, 10) == pytest.approx(20) and time_to_breach(None, 10) == math.inf
    t, d = closest_approach(100, 0, 0, -10, 0, 0, 60)  # head-on along x
    assert t == pytest.approx(10) and d == pytest.approx(0)
    t, d = closest_approach(100, 30, 0, -10, 0, 0, 5)  # clamped to the horizon
    assert t == 5 and d == pytest.approx(math.hypot(50, 30))
    t, d = closest_approach(100, 0, 0, 10, 0, 0, 60)  # diverging
    assert t == 0 and d == pytest.approx(100)
    assert dynamic_radius(50, 20) == pytest.approx(90) and dynamic_radius(50, -5) == 50


def test_replay_straight_run_at_a_fence(fences):
    """10 m/s north at the keep-out square: WARNING well before, IMMINENT before, BREACH at it."""
    sm = StateMachine(hold_s=2.0)
    first = {}
    for step in range(0, 300):
        t = step * 0.1
        y = 10.0 * t
        check = fences.check(50, y, alt=20, vx=0, vy=10, lookahead_m=10 * 30)
        level, changed = sm.update(assess(check, 10.0, horizon_s=15).level, t)
        if changed:
            first.setdefault(level, t)
    breach = first[Level.BREACH]
    assert breach == pytest.approx(20.0, abs=0.11)  # the fence is 200 m away
    assert breach - first[Level.WARNING] >= 3.0
    assert breach - first[Level.IMMINENT] >= (stopping_distance(10) - 2.0) / 10 - 0.2


def test_hysteresis_does_not_flap():
    sm = StateMachine(hold_s=2.0)
    assert sm.update(Level.WARNING, 0.0) == (Level.WARNING, True)
    assert sm.update(Level.CLEAR, 0.5) == (Level.WARNING, False)
    assert sm.update(Level.WARNING, 1.0) == (Level.WARNING, False)  # back before the hold ran out
    assert sm.update(Level.CLEAR, 1.5) == (Level.WARNING, False)
    assert sm.update(Level.CLEAR, 3.6) == (Level.CLEAR, True)
    assert sm.update(Level.BREACH, 3.7) == (Level.BREACH, True)  # escalation is immediate
