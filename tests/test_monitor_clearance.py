"""The engine's shortcut for positions far from every fence (alphafence.awareness.clearance)
decides exactly what the full check decides: property-tested over random fences (keep-out,
warning layers, keep-in, altitude bands, a time window) and random flights, with the shortcut
on and off, event for event and level for level."""

import math
from datetime import datetime, timezone

import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.options import MonitorOptions

FRAME = LocalFrame(14.5, 35.9)

box = st.tuples(st.floats(-600, 600), st.floats(-600, 600), st.floats(5, 300), st.floats(5, 300))
fence = st.tuples(
    st.sampled_from(["keep_out", "keep_out", "warning", "keep_in"]),
    box,
    st.one_of(st.none(), st.tuples(st.floats(0, 60), st.floats(61, 200))),
)
leg = st.tuples(st.floats(-math.pi, math.pi), st.floats(0, 25), st.integers(5, 80))


def fence_set(specs):
    records = []
    for i, (kind, (x, y, w, h), band) in enumerate(specs):
        geom = FRAME.geom_to_wgs84(shapely.box(x, y, x + w, y + h))
        lo, hi = band if band else (None, None)
        records.append(FenceRecord(f"site/{i}", kind, geom, 0.0, alt_min_m=lo, alt_max_m=hi))
    return FenceSet(records, frame=FRAME)


def flight(legs, alt0, y0=-1800.0, x0=0.0):
    t, x, y, alt = 0.0, x0, y0, alt0
    for heading, speed, n in legs:
        vx, vy = speed * math.sin(heading), speed * math.cos(heading)
        for _ in range(n):
            t += 0.1
            x, y, alt = x + vx * 0.1, y + vy * 0.1, max(0.0, alt + math.sin(t) * 0.5)
            lon, lat = FRAME.to_wgs84(x, y)
            yield Sample(t, float(lat), float(lon), alt, vn=vy, ve=vx, mode="GUIDED", armed=True)


def both(specs, legs, alt0, enforce, start):
    out = []
    for shortcut in (True, False):
        engine = Engine(fence_set(specs), MonitorOptions(enforce=enforce))
        engine.shortcut = shortcut
        steps = [(engine.step(s), engine.sm.level) for s in flight(legs, alt0, *start)]
        # each engine anchors its events' UTC to the wall clock when it starts: the two can
        # differ by a millisecond, which is no decision of theirs
        steps = [([{k: v for k, v in e.items() if k != "utc"} for e in events], level)
                 for events, level in steps]  # fmt: skip
        out.append((steps, engine.checks))
    return out


@settings(max_examples=200, deadline=None)
@example(  # head-on at a keep-out from 400 m: the warning must come as early
    specs=[("keep_out", (-50.0, 0.0, 100.0, 100.0), None)],
    legs=[(0.0, 10.0, 80)],
    alt0=30.0,
    enforce=True,
    start=(-400.0, 0.0),
)
@example(  # into a warning layer with the nearest keep-out 2 km away
    specs=[
        ("warning", (-50.0, 0.0, 100.0, 100.0), None),
        ("keep_out", (0.0, 2000.0, 50, 50), None),
    ],
    legs=[(0.0, 10.0, 300)],
    alt0=30.0,
    enforce=False,
    start=(-200.0, 0.0),
)
@given(
    specs=st.lists(fence, min_size=1, max_size=6),
    legs=st.lists(leg, min_size=1, max_size=6),
    alt0=st.floats(0, 150),
    enforce=st.booleans(),
    start=st.tuples(st.floats(-900, 900), st.floats(-900, 900)),
)
def test_the_shortcut_decides_what_the_full_check_decides(specs, legs, alt0, enforce, start):
    (fast, n_fast), (full, n_full) = both(specs, legs, alt0, enforce, start)
    assert fast == full
    assert n_fast == n_full


def test_a_flight_away_from_fences_mostly_takes_the_shortcut():
    specs = [("keep_out", (-100, 0, 200, 200), None), ("warning", (-130, -30, 260, 260), None)]
    engine = Engine(fence_set(specs), MonitorOptions())
    full = []
    real = engine.fences.check

    def counted(*args, **kwargs):
        full.append(args)
        return real(*args, **kwargs)

    engine.fences.check = counted
    samples = list(flight([(0.0, 10.0, 100)], 30.0))  # 10 s north, ending 800 m short of it
    for s in samples:
        engine.step(s)
    assert engine.checks == len(samples)
    assert len(full) < len(samples) / 4, len(full)


def test_a_time_window_opening_ends_the_shortcut():
    # a keep-out that opens while the vehicle is 200 m from it: the next position is checked
    # in full (the fences' version changed) and the warning comes as without the shortcut
    window = {"startDateTime": "2026-01-01T10:00:00Z", "endDateTime": "2026-01-01T11:00:00Z"}
    geom = FRAME.geom_to_wgs84(shapely.box(-50, 0, 50, 100))
    zone = {"zone": {"applicability": [window]}}
    fences = FenceSet([FenceRecord("event/1", "keep_out", geom, 0.0, properties=zone)], FRAME)
    assert fences.timed == [0]
    engine = Engine(fences, MonitorOptions())
    fences.set_time(datetime(2026, 1, 1, 9, tzinfo=timezone.utc))
    version = fences.version
    samples = list(flight([(0.0, 10.0, 180)], 30.0, y0=-300.0))  # up to 120 m short of it
    for s in samples[:60]:
        engine.step(s)
    fences.set_time(datetime(2026, 1, 1, 10, 30, tzinfo=timezone.utc))
    assert fences.version != version
    events = []
    for s in samples[60:]:
        events += engine.step(s)
    assert any(e.get("level") in ("WARNING", "IMMINENT") for e in events), events
    # and nothing before: closed, the zone is no fence
    fences.set_time(datetime(2026, 1, 1, 9, tzinfo=timezone.utc))
    quiet = Engine(fences, MonitorOptions())
    assert not [e for s in samples for e in quiet.step(s) if e.get("level")]
