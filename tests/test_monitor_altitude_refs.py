"""The monitor compares each fence's altitude band with the vehicle's altitude in the band's own
reference: AMSL limits (ED-269, ED-318, KML ``absolute``, OpenAir ``MSL``) with the altitude
AMSL, AGL limits and limits without a reference with the height above home. Position check,
prediction, replay of a trace without altitudes AMSL, the home moving."""

import math

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.options import MonitorOptions
from alphafence.review.replay import Trace, replay

FRAME = LocalFrame(14.5, 35.9)
HOME_AMSL = 150.0
SQUARE = shapely.box(-50, 200, 50, 300)  # 200 m north of home


def zone(ref, lo=0.0, hi=200.0, ed269=True, kind="keep_out"):
    """A 0-200 m zone whose limits are referenced to ``ref`` (None: no reference), kept as
    ED-269 keeps it (in ``zone``) or as KML and OpenAir do (on the fence)."""
    refs = {} if ref is None else {"lower_reference": ref, "upper_reference": ref}
    props = {"zone": refs} if ed269 else dict(refs)
    geom = FRAME.geom_to_wgs84(SQUARE)
    return FenceRecord("zone/1", kind, geom, 0.0, alt_min_m=lo, alt_max_m=hi, properties=props)


def at(x, y, rel, t=0.0, amsl=True, vn=0.0, vd=0.0):
    lon, lat = FRAME.to_wgs84(x, y)
    alt_amsl = rel + HOME_AMSL if amsl else None
    return Sample(t, float(lat), float(lon), rel, vn=vn, mode="GUIDED", armed=True,
                  alt_amsl_m=alt_amsl, vd=vd)  # fmt: skip


def level_at(record, rel, amsl=True):
    """The engine's level for a vehicle hovering in the zone's footprint at ``rel`` above home."""
    engine = Engine(FenceSet([record], frame=FRAME), MonitorOptions(onboard="off"))
    events = engine.step(at(0.0, 250.0, rel, amsl=amsl))
    return engine.sm.level.name, events


@pytest.mark.parametrize("ed269", [True, False])
def test_an_amsl_band_is_compared_with_the_altitude_amsl(ed269):
    # 0-200 m AMSL, home at 150 m AMSL: 100 m above home is 250 m AMSL, 50 m over the zone
    level, events = level_at(zone("AMSL", ed269=ed269), 100.0)
    assert level == "CLEAR" and not events
    # 30 m above home is 180 m AMSL: inside
    assert level_at(zone("MSL", ed269=ed269), 30.0)[0] == "BREACH"
    # a floor AMSL: 180-400 m AMSL, 5 m above home (155 m AMSL) is 25 m under it
    assert level_at(zone("AMSL", lo=180.0, hi=400.0, ed269=ed269), 5.0)[0] == "CLEAR"
    assert level_at(zone("AMSL", lo=180.0, hi=400.0, ed269=ed269), 35.0)[0] == "BREACH"
    # 5 m under a floor at 160 m AMSL: within the vertical margin, the fence is at hand
    level, events = level_at(zone("AMSL", lo=160.0, hi=400.0, ed269=ed269), 5.0)
    assert level == "IMMINENT" and events[0]["reason"] == "at the fence margin"


@pytest.mark.parametrize("ref", ["AGL", "SFC", None])
def test_agl_bands_and_bands_without_reference_use_the_height_above_home(ref):
    level, events = level_at(zone(ref), 100.0)
    assert level == "BREACH"
    (e,) = [e for e in events if e["event"] == "level"]
    assert e["fence"] == "zone/1" and e["reason"] == "inside a keep-out fence"
    assert level_at(zone(ref), 250.0)[0] == "CLEAR"  # over it: 250 m above home


def test_the_position_check_and_the_fence_arrays_follow_home():
    fs = FenceSet([zone("AMSL"), zone("AGL"), zone(None)], frame=FRAME)
    # no home yet: an AMSL limit cannot be placed, the zone counts at every altitude
    assert fs.home_amsl is None and fs.check(0, 250, alt=5000).inside_keep_out == [0]
    assert fs.set_home(HOME_AMSL)
    assert fs.alt_max.tolist() == [50.0, 200.0, 200.0] and fs.alt_min[0] == -150.0
    assert fs.check(0, 250, alt=100).inside_keep_out == [1, 2]
    assert not fs.set_home(HOME_AMSL + 0.004)  # the same home, to rounding: nothing moves
    assert fs.set_home(250.0)  # re-armed on a hill: the AMSL zone is now under the vehicle
    assert fs.alt_max[0] == -50.0 and fs.check(0, 250, alt=-100).inside_keep_out == [0]
    assert fs.check(0, 250, alt=1).inside_keep_out == [1, 2]


def run_north(record, rel, vd=0.0, amsl=True):
    """10 m/s north from home at ``rel`` above home toward the zone (200 m away)."""
    engine = Engine(FenceSet([record], frame=FRAME), MonitorOptions(onboard="off"))
    levels = []
    for k in range(260):
        s = at(0.0, k * 1.0, rel - vd * k * 0.1, t=k * 0.1, vn=10.0, vd=vd, amsl=amsl)
        levels += [e["level"] for e in engine.step(s) if e["event"] == "level"]
    return levels


def test_the_prediction_follows_the_reference():
    # over an AMSL zone by 50 m and level: nothing predicted, nothing entered
    assert run_north(zone("AMSL"), 100.0) == []
    # the same height under an AGL 0-200 zone: warned, imminent, then inside
    assert run_north(zone("AGL"), 100.0) == ["WARNING", "IMMINENT", "BREACH"]
    # descending at 4 m/s from 100 m above home toward the AMSL zone's top (50 m above home):
    # predicted while still above it
    levels = run_north(zone("AMSL"), 100.0, vd=4.0)
    assert levels[:2] == ["WARNING", "IMMINENT"]


def test_a_trace_without_altitudes_amsl_flags_amsl_bands():
    fs = FenceSet([zone("AMSL")], frame=FRAME)
    trace = Trace("synthetic", samples=[at(0.0, 250.0 + k, 100.0, t=k * 0.1, amsl=False)
                                        for k in range(3)])  # fmt: skip
    events = replay(trace, fs, MonitorOptions(onboard="off"))
    flag = [e for e in events if e["event"] == "altitude_unknown"]
    assert len(flag) == 1 and flag[0]["fences"] == ["zone/1"]
    assert "every altitude" in flag[0]["reason"]
    # the zone counts at every altitude meanwhile: the vehicle at 100 m above home is in it
    assert [e["level"] for e in events if e["event"] == "level"] == ["BREACH"]
    # a fence without an AMSL limit: as before, and no flag
    fs = FenceSet([zone(None)], frame=FRAME)
    events = replay(trace, fs, MonitorOptions(onboard="off"))
    assert not [e for e in events if e["event"] == "altitude_unknown"]
    assert [e["level"] for e in events if e["event"] == "level"] == ["BREACH"]


def test_a_known_home_outlives_a_sample_without_altitude_amsl():
    engine = Engine(FenceSet([zone("AMSL")], frame=FRAME), MonitorOptions(onboard="off"))
    assert engine.step(at(0.0, 250.0, 100.0)) == []
    s = at(0.0, 250.0, 100.0, t=0.1)
    s.alt_amsl_m = math.nan  # a link without it for a while: the home stays where it was
    assert engine.step(s) == [] and engine.fences.home_amsl == HOME_AMSL


@pytest.mark.parametrize("n", [20, 300])  # measured directly; searched in growing squares
def test_the_nearest_keep_out_in_reach_is_the_nearest(n):
    import numpy as np

    rng = np.random.default_rng(n)
    records = []
    for i in range(n):
        x, y = rng.uniform(-3000, 3000, 2)
        lo = float(rng.uniform(0, 300))
        ref = ["AMSL", "AGL", None][i % 3]
        rec = zone(ref, lo=lo, hi=lo + float(rng.uniform(5, 100)))
        geom = FRAME.geom_to_wgs84(shapely.box(x, y, x + 40, y + 40))
        band = dict(alt_min_m=rec.alt_min_m, alt_max_m=rec.alt_max_m)
        records.append(FenceRecord(f"z/{i}", "keep_out", geom, properties=rec.properties, **band))
    fs = FenceSet(records, frame=FRAME)
    fs.set_home(HOME_AMSL)
    for _ in range(200):
        x, y = (float(v) for v in rng.uniform(-4000, 4000, 2))
        alt = float(rng.uniform(-50, 400))
        got = fs.check(x, y, alt, vertical_m=10.0).nearest_keep_out
        d = shapely.distance(shapely.Point(x, y), fs.local)
        reach = (fs.alt_min - 10.0 <= alt) & (alt <= fs.alt_max + 10.0)
        if not reach.any():
            assert got is None
            continue
        want = float(d[reach].min())
        assert got is not None and reach[got.index]
        assert got.distance_m == pytest.approx(want, abs=1e-6)
