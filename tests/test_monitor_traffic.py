"""Dynamic fences around other aircraft: CPA-based conflicts, growing radius, stale reports."""

import pytest

from alphafence.awareness.traffic import Aircraft, Traffic, TrafficOptions


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


def test_engine_turns_adsb_reports_into_conflict_events():
    import json

    import shapely

    from alphafence.awareness.fenceset import FenceSet
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.geo.frame import LocalFrame
    from alphafence.monitor.engine import Engine, Sample
    from alphafence.monitor.events import alert_text
    from alphafence.monitor.feeds import parse_adsb

    frame = LocalFrame(-0.55, 51.43)
    far = frame.geom_to_wgs84(shapely.box(5000, 5000, 5100, 5100))
    eng = Engine(FenceSet([FenceRecord("x", "keep_out", far)], frame=frame))
    lon, lat = frame.to_wgs84(0.0, 600.0)  # 600 m north, flying south at 60 m/s, 120 m AMSL
    msg = {
        "ICAO_address": 0x4CA123,
        "lat": round(float(lat) * 1e7),
        "lon": round(float(lon) * 1e7),
        "altitude": 120_000,
        "heading": 18000,
        "hor_velocity": 6000,
        "ver_velocity": 0,
        "callsign": "RYR1\x00\x00",
    }
    report = parse_adsb(json.dumps(msg))
    assert report["callsign"] == "RYR1" and report["vn"] == pytest.approx(-60, abs=1e-6)
    eng.aircraft(t=0.0, **report)
    own = Sample(0.0, 51.43, -0.55, 20.0, alt_amsl_m=100.0)
    events = eng.step(own)
    conflict = [e for e in events if e["event"] == "traffic_conflict"]
    assert conflict and conflict[0]["callsign"] == "RYR1"
    assert conflict[0]["t_cpa_s"] == pytest.approx(10.0, abs=0.1)
    assert alert_text(conflict[0]).startswith("AF TRAFFIC RYR1")
    assert [
        e
        for e in eng.step(Sample(0.5, 51.43, -0.55, 20.0, alt_amsl_m=100.0))
        if e["event"] == "traffic_conflict"
    ] == []
    assert parse_adsb(json.dumps({**msg, "lat": 0, "lon": 0})) is None
    assert parse_adsb("not json") is None


def test_other_mavlink_systems_become_traffic():
    import json

    from alphafence.monitor.feeds import parse_global_position

    r = parse_global_position(
        7,
        json.dumps(
            {
                "lat": 514300000,
                "lon": -5500000,
                "alt": 120000,
                "relative_alt": 0,
                "vx": 500,
                "vy": -300,
                "vz": -100,
                "hdg": 0,
            }
        ),
    )
    assert r["key"] == "mavlink/7" and r["callsign"] == "MAV7"
    assert (r["vn"], r["ve"], r["vu"]) == (5.0, -3.0, 1.0) and r["alt_amsl_m"] == 120.0
    assert parse_global_position(7, json.dumps({"lat": 0, "lon": 0, "alt": 0})) is None
