"""Dynamic fences around other aircraft: CPA-based conflicts, growing radius, stale reports."""

import pytest

from kit.monitor.traffic import Aircraft, Traffic, TrafficOptions


def test_head_on_traffic_is_a_conflict_with_its_time():
    tr = Traffic(TrafficOptions(horizontal_m=150, vertical_m=50, reaction_s=2))
    tr.report(
        Aircraft("4CA123", 0.0, 0.0, 2000.0, 100.0, 0.0, -40.0, callsign="RYR1")
    )  # 40 m/s south
    c = tr.conflicts(0.0, 0.0, 0.0, 100.0, 0.0, 10.0, horizon_s=60)  # we fly north at 10 m/s
    assert len(c) == 1 and c[0].callsign == "RYR1"
    assert c[0].t_cpa_s == pytest.approx(40.0)  # 2000 m closing at 50 m/s
    assert c[0].radius_m == pytest.approx(150 + 50 * 2)  # grows with the closing speed
    assert not c[0].now


def test_no_conflict_beyond_horizon_parallel_or_separated_vertically():
    tr = Traffic()
    tr.report(Aircraft("far", 0.0, 0.0, 20000.0, 100.0, 0.0, -40.0))
    tr.report(Aircraft("parallel", 0.0, 400.0, 0.0, 100.0, 0.0, 10.0))
    tr.report(Aircraft("high", 0.0, 0.0, 500.0, 600.0, 0.0, -40.0))
    assert tr.conflicts(0.0, 0.0, 0.0, 100.0, 0.0, 10.0, horizon_s=30) == []


def test_stale_reports_are_dropped_and_dead_reckoned_until_then():
    tr = Traffic(TrafficOptions(stale_s=10))
    tr.report(Aircraft("a", 0.0, 0.0, 1000.0, 100.0, 0.0, -50.0))
    # 5 s later it has flown 250 m south: 750 m away and closing at 50 m/s -> CPA in 15 s
    c = tr.conflicts(5.0, 0.0, 0.0, 100.0, 0.0, 0.0, horizon_s=60)
    assert c and c[0].t_cpa_s == pytest.approx(15.0)
    assert tr.conflicts(20.0, 0.0, 0.0, 100.0, 0.0, 0.0) == [] and "a" not in tr.aircraft


def test_an_older_report_never_replaces_a_newer_one():
    tr = Traffic()
    tr.report(Aircraft("a", 2.0, 0.0, 500.0, 100.0, 0.0, 0.0))
    tr.report(Aircraft("a", 1.0, 0.0, 5000.0, 100.0, 0.0, 0.0))
    assert tr.aircraft["a"].y == 500.0
