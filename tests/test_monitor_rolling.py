"""The rolling onboard fence (``monitor --onboard rolling``): the plan's selection and hysteresis
(pure, property-tested: whatever the vehicle does within its speed limit, the fence in force
holds every fence within its reach, and the compiled fence contains them), and the re-upload
against the scripted ArduPilot peer (tests/fake_vehicle.py) through MAVSDK: a verified upload
is an event and reloads the onboard layer; a failed one is an event and an alert, and the
vehicle keeps its previous fence."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
import shapely
from hypothesis import event, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import Braking
from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.storage import PROFILES, Profile, storage_bytes
from alphafence.monitor import rolling as rolling_module
from alphafence.monitor.engine import Sample
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.options import MonitorOptions, RollingOptions
from alphafence.monitor.rolling import RollingPlan
from alphafence.monitor.runner import Monitor
from alphafence.onboard.compile import compile_fences
from alphafence.vehicle.link import open_vehicle
from tests.fake_vehicle import FakeVehicle, Faults

from .helpers import until

FRAME = LocalFrame(14.486, 35.891)
BRAKING = Braking()
OPTIONS = RollingOptions()  # 10 m/s, 30 s: reach 337 m, trigger 84 m, radius 471 m
REACH = OPTIONS.reach_m(BRAKING)


def squares(centres, size=30.0, kind="keep_out"):
    """Square fences (``size`` m) at metric ``centres``, as records."""
    return [
        FenceRecord(
            f"site/{k}",
            kind,
            FRAME.geom_to_wgs84(
                shapely.box(x - size / 2, y - size / 2, x + size / 2, y + size / 2)
            ),
        )
        for k, (x, y) in enumerate(centres)
    ]


def plan_for(records, options=OPTIONS):
    return RollingPlan(
        FenceSet(records, FRAME),
        options.reach_m(BRAKING),
        options.trigger_m(BRAKING),
        options.radius_m(BRAKING),
    )


def sample_at(x, y, t=0.0):
    lon, lat = FRAME.to_wgs84(x, y)
    return Sample(t, float(lat), float(lon), 20.0, armed=True)


# -- the plan (pure) ---------------------------------------------------------------------


def test_reach_is_the_lookahead_at_the_speed_limit_and_the_stop():
    assert REACH == pytest.approx(10 * 30 + 10 * 1.5 + 10**2 / (2 * 2.5) + 2.0)
    assert OPTIONS.radius_m(BRAKING) == pytest.approx(REACH * 1.25 + 10 * 5.0)
    fast = RollingOptions(speed_mps=20.0, lookahead_s=10.0)
    assert fast.reach_m(BRAKING) == pytest.approx(200 + 30 + 80 + 2)
    for bad in ({"speed_mps": 0}, {"lookahead_s": -1}, {"hysteresis": 1.5}, {"retry_s": 0}):
        with pytest.raises(InputError):
            RollingOptions(**bad)
    with pytest.raises(InputError):
        MonitorOptions(onboard="roll")


def test_the_plan_selects_keep_out_and_keep_in_fences_within_reach_not_warnings():
    records = squares([(0, 200), (0, 600)]) + squares([(100, 0)], kind="warning")
    records[1] = FenceRecord("site/far", "keep_in", records[1].geometry)
    plan = plan_for(records)
    assert plan.within(0, 0, REACH) == ["site/0"]
    assert plan.within(0, 300, REACH) == ["site/0", "site/far"]
    assert plan.coverage(0, 0, 14.486, 35.891).sites == {"site/0"}  # 600 m: beyond 471


def test_hysteresis_one_upload_per_trigger_distance_and_none_while_hovering():
    plan = plan_for(squares([(0, 200)]))
    coverage, uploads = None, []
    for k in range(0, 3001):  # 3 km north in 1 m steps, each fence uploaded at once
        why = plan.due(coverage, 0.0, float(k))
        if why is not None:
            uploads.append((k, why))
            coverage = plan.coverage(0.0, float(k), 0.0, 0.0)
    assert uploads[0] == (0, "start")
    assert {why for _, why in uploads[1:]} == {"moved"}
    trigger = OPTIONS.trigger_m(BRAKING)
    assert len(uploads) == 1 + int(3000 // math.floor(trigger + 1))
    assert all(b - a == math.floor(trigger) + 1 for (a, _), (b, _) in zip(uploads, uploads[1:]))
    cx, cy = coverage.x, coverage.y
    hover = [plan.due(coverage, cx + math.cos(a) * 50, cy + math.sin(a) * 50) for a in range(50)]
    assert set(hover) == {None}  # circling 50 m around the last centre: no upload


def test_the_plan_says_uncovered_when_the_vehicle_outruns_its_fence():
    plan = plan_for(squares([(0, 700)]))
    coverage = plan.coverage(0.0, 0.0, 0.0, 0.0)
    assert "site/0" not in coverage.sites
    edge = OPTIONS.radius_m(BRAKING) - REACH
    assert plan.due(coverage, 0.0, edge - 1) == "moved"
    assert plan.due(coverage, 0.0, edge + 1) == "uncovered"
    assert not plan.covers(coverage, 0.0, 700.0 - REACH + 1)  # the fence is within reach now
    assert plan.covers(coverage, 0.0, edge + 1)  # beyond the disk, but no fence is missing


headings = st.lists(st.floats(0, 2 * math.pi), min_size=1, max_size=40)
anywhere = st.tuples(st.floats(-1500, 1500), st.floats(-1500, 1500))
STEPS = 200  # seconds flown in the hysteresis property


def offset(x, y, distance, angle):
    return (x + distance * math.cos(angle), y + distance * math.sin(angle))


def track(turns, speed):
    """The vehicle's position at each second: from (0, 0) at ``speed`` m/s, heading
    ``turns[k]`` for the k-th equal share of the flight."""
    x = y = 0.0
    out = []
    for step in range(STEPS):
        out.append((x, y))
        heading = turns[step * len(turns) // STEPS]
        x, y = offset(x, y, speed, heading)
    return out


@st.composite
def flights(draw):
    """A flight within the speed limit, turning at will, and fences beside its track: each
    within 1.5 reaches of a position it passes (so the fence in force must hold some of them
    after the vehicle has moved, and leave others out), and a few anywhere."""
    turns = draw(headings)
    speed_fraction = 1.0 - draw(st.floats(0.0, 0.95))  # 0.05 to 1, small draws favoured: fast
    positions = track(turns, OPTIONS.speed_mps * speed_fraction)
    beside = st.tuples(
        st.integers(0, STEPS - 1), st.floats(0, 1.5 * REACH), st.floats(0, 2 * math.pi)
    )
    centres = [  # counted from the end (small integers are favoured): where it has moved
        offset(*positions[-1 - k], distance, angle)
        for k, distance, angle in draw(st.lists(beside, min_size=1, max_size=20))
    ]
    return turns, speed_fraction, centres + draw(st.lists(anywhere, max_size=5))


@settings(max_examples=60, deadline=None)
@given(flights(), st.floats(0.2, 1.0), st.integers(0, 5))
def test_the_fence_in_force_holds_every_fence_within_reach(flight, hysteresis, latency_steps):
    """A vehicle within its speed limit, turning at will; each re-upload written
    ``latency_steps`` seconds after it is due (at most the upload budget): at every second the
    fence in force (the one written last) holds every fence within reach of the vehicle."""
    turns, speed_fraction, centres = flight
    options = RollingOptions(hysteresis=hysteresis, upload_budget_s=5.0)
    plan = plan_for(squares(centres), options)
    in_force, pending = None, None  # (coverage, written at step)
    writes, held = 0, 0  # fences written; held: 1 a fence within reach under the first, 2 under
    # a re-uploaded one (what the property is about: the vehicle has moved)
    for step, (x, y) in enumerate(track(turns, options.speed_mps * speed_fraction)):
        if pending is not None and step >= pending[1]:
            in_force, pending = pending[0], None
            writes += 1
        if in_force is not None:
            within = set(plan.within(x, y, plan.reach_m))
            assert within <= in_force.sites
            assert plan.covers(in_force, x, y)
            held = max(held, (1 + (writes > 1)) if within else 0)
        if pending is None and plan.due(in_force, x, y) is not None:
            pending = (plan.coverage(x, y, 0.0, 0.0), step + latency_steps)
            if in_force is None:  # the start: nothing to hold until the first is written
                in_force, pending = pending[0], None
                writes += 1
    event(
        (
            "vacuous: no fence ever within reach",
            "asserted: fences within reach held by the first fence only",
            "asserted: fences within reach held by a re-uploaded fence",
        )[held]
    )


RADIUS = OPTIONS.radius_m(BRAKING)


@st.composite
def rolling_scenes(draw):
    """Fences and a position the fence compiled at (0, 0) is for (within its radius less the
    reach: the vehicle anywhere else calls for a new one): fences within reach of the
    position, often so many more within the radius that the compile must merge to fit a
    copter's 560 bytes (merging starts at about 20 squares), and a few anywhere."""
    px, py = offset(0.0, 0.0, draw(st.floats(0, RADIUS - REACH)), draw(st.floats(0, 2 * math.pi)))
    polar = st.tuples(st.floats(0, 1), st.floats(0, 2 * math.pi))
    near = [offset(px, py, REACH * r, a) for r, a in draw(st.lists(polar, min_size=1, max_size=8))]
    count = draw(st.integers(4, 50))  # a count of its own: hypothesis favours short lists
    around = [
        offset(0, 0, RADIUS * r, a)
        for r, a in draw(st.lists(polar, min_size=count, max_size=count))
    ]
    return near + around + draw(st.lists(anywhere, max_size=5)), px, py


@settings(max_examples=25, deadline=None)
@given(rolling_scenes())
def test_the_compiled_rolling_fence_contains_every_fence_within_reach(scene):
    """What is uploaded (the copter's 560 bytes) contains every fence within reach of any
    position the fence in force is for."""
    centres, px, py = scene
    records = squares(centres, size=60.0)
    plan = plan_for(records)
    centre = plan.coverage(0.0, 0.0, FRAME.lon0, FRAME.lat0)
    try:
        compiled = compile_fences(
            plan.records(centre),
            shapely.Point(FRAME.lon0, FRAME.lat0),
            PROFILES["copter"],
            centre.radius_m + 1.0,
        )
    except InputError:  # too many to fit even merged: an event, nothing uploaded (tested below)
        event("early: too many to fit")
        return
    assert len(compiled.items) <= 70 and compiled.bytes_used <= 560
    onboard = shapely.union_all(
        [compiled.frame.geom_to_wgs84(p.chosen.local) for p in compiled.pieces]
    )
    if plan.due(centre, px, py) == "uncovered":
        event("early: uncovered")
        return
    near = plan.indices(px, py, REACH)
    event(f"asserted: {'merged' if compiled.merges else 'not merged'}" if near else "vacuous")
    for i in near:
        fence = plan.fences.records[i].geometry
        assert shapely.covers(shapely.buffer(onboard, 1e-8), fence), plan.fences.records[i].site_id


# -- against the scripted peer -----------------------------------------------------------

# four 30 m squares along the first 2 km north, 60 m east of the track
TRACK_FENCES = squares([(60, 150), (60, 700), (-60, 1300), (60, 1900)])


class Alerts:
    def __init__(self):
        self.texts = []

    async def __call__(self, text, event):
        self.texts.append(text)


async def monitor_on(fake, body, options=None):
    """A rolling monitor on a MAVSDK connection to ``fake``; ``body(monitor)`` then stop."""
    options = options or MonitorOptions(onboard="rolling")
    async with open_vehicle(fake.url, 10) as vehicle:
        log = EventLog(None)
        monitor = Monitor(vehicle, FenceSet(TRACK_FENCES, FRAME), options, log)
        monitor.commands.alert = alerts = Alerts()
        stop = asyncio.Event()
        task = asyncio.create_task(monitor.run(stop))
        try:
            await until(lambda: monitor.tasks, "run() started (and the first download with it)")
            await body(monitor)
            assert not task.done(), "the monitor stopped by itself"
        finally:
            stop.set()
            await asyncio.wait_for(task, 10)
    return list(log.events), alerts.texts


def kinds(events, *names):
    return [e for e in events if e["event"] in names]


async def test_a_rolling_upload_is_verified_an_event_and_the_onboard_layer_follows():
    async with FakeVehicle() as fake:

        async def body(monitor):
            rolling = monitor.rolling
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 0)), 30) is True
            assert rolling.consider(sample_at(0, 50)) is None  # within the hysteresis
            first = list(fake.fence)
            # 100 m on: the same fences, the same items: nothing sent, the centre moves
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 100)), 30) is True
            assert (
                rolling.uploads == 1 and fake.fence_writes == 1 and round(rolling.coverage.y) == 100
            )
            # 230 m: the fence 700 m north is within the radius (471 m) now
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 230)), 30) is True
            assert rolling.uploads == 2 and fake.fence != first

        events, alerts = await monitor_on(fake, body)
        assert fake.fence_writes == 2
    ups = kinds(events, "onboard_upload")
    assert [u["reason"] for u in ups] == ["start", "moved"]
    for u in ups:
        assert u["verified"] is True and u["items"] > 0 and u["seconds"] > 0
        assert u["bytes"] <= 560 and u["reach_m"] == round(REACH, 2)
    assert [u["fences"] for u in ups] == [1, 2]
    assert kinds(events, "onboard_kept")[0]["reason"] == "moved"
    assert ups[1]["centre"][0] > ups[0]["centre"][0]
    # what the vehicle holds is what the last upload said, and the onboard layer followed
    assert len(fake.fence) == ups[-1]["items"] and storage_bytes(fake.fence) == ups[-1]["bytes"]
    loads = kinds(events, "onboard_fence", "onboard_none")
    assert [e.get("cause") for e in loads] == ["start", "rolling", "rolling"]
    assert loads[-1]["items"] == ups[-1]["items"]
    assert alerts == ["AF no onboard fence"]  # the start: SITL and the fake hold none


async def test_no_fence_within_the_radius_sends_nothing():
    async with FakeVehicle() as fake:

        async def body(monitor):
            assert await asyncio.wait_for(monitor.rolling.consider(sample_at(0, -900)), 30)
            assert monitor.rolling.coverage is not None and monitor.rolling.uploads == 0

        events, _ = await monitor_on(fake, body)
        assert fake.fence_writes == 0
    (kept,) = kinds(events, "onboard_kept")
    assert kept["items"] == 0 and kept["fences"] == 0


class Clock:
    """The rolling monitor's clock (its module's ``time``), moved ahead by the test: the
    monotonic clock plus ``ahead`` seconds."""

    def __init__(self):
        self.ahead = 0.0

    def monotonic(self):
        return time.monotonic() + self.ahead

    def __getattr__(self, name):
        return getattr(time, name)


async def test_a_failed_re_upload_keeps_the_old_fence_and_is_an_event_and_an_alert(monkeypatch):
    """The vehicle refuses an item mid-upload; ArduPilot (and the fake) keep the fence they
    had; the monitor says so, alerts, keeps checking against the old fence and tries again
    after ``retry_s`` (on its own clock, which the test moves ahead: no wait, no race)."""
    clock = Clock()
    monkeypatch.setattr(rolling_module, "time", clock)
    options = MonitorOptions(onboard="rolling", rolling=RollingOptions(retry_s=600.0))
    async with FakeVehicle() as fake:

        async def body(monitor):
            rolling = monitor.rolling
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 0)), 30) is True
            before, layer, coverage = list(fake.fence), monitor.engine.onboard, rolling.coverage
            fake.faults = Faults(nack_item=(3, mav.MAV_MISSION_ERROR), nack_text="Bad item")
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 600)), 30) is False
            assert fake.fence == before and rolling.coverage is coverage
            assert monitor.engine.onboard.items == layer.items  # reloaded: the same fence
            assert rolling.consider(sample_at(0, 601)) is None  # not before retry_s
            clock.ahead += 599.0
            assert rolling.consider(sample_at(0, 601.5)) is None  # still not
            fake.faults = Faults()
            clock.ahead += 1.0  # retry_s since the failure: the next position tries again
            assert await asyncio.wait_for(rolling.consider(sample_at(0, 602)), 30) is True

        events, alerts = await monitor_on(fake, body, options)
    (failed,) = kinds(events, "onboard_upload_failed")
    assert failed["stage"] == "upload" and failed["verified"] is False
    assert "still holds its previous fence" in failed["kept"]
    assert "Bad item" in failed["error"]
    assert "AF onboard upload failed: old fence kept" in alerts
    behind = kinds(events, "onboard_behind")
    assert len(behind) == 1  # 600 m from the first centre: once, not at every position
    assert [u["reason"] for u in kinds(events, "onboard_upload")] == ["start", "uncovered"]


async def test_fences_that_do_not_fit_are_a_compile_event_and_nothing_is_sent():
    options = MonitorOptions(
        onboard="rolling", rolling=RollingOptions(profile=Profile("tiny", 1, 10))
    )
    async with FakeVehicle() as fake:

        async def body(monitor):
            assert await asyncio.wait_for(monitor.rolling.consider(sample_at(0, 0)), 30) is False

        events, alerts = await monitor_on(fake, body, options)
        assert fake.fence_writes == 0
    (failed,) = kinds(events, "onboard_upload_failed")
    assert failed["stage"] == "compile" and "nothing was sent" in failed["kept"]
    assert "AF onboard compile failed: old fence kept" in alerts


def test_cli_rolling_options(tmp_path, capsys):
    from alphafence.cli.monitor import _rolling_options

    class Args:
        onboard, profile, sd_fence_kb, speed_limit, reach_time = "rolling", None, None, 12.0, 20.0

    o = _rolling_options(Args)  # the profile is the vehicle's autopilot's, once connected
    assert o.profile is None and o.speed_mps == 12.0 and o.lookahead_s == 20.0
    Args.profile, Args.sd_fence_kb = "navio2", 8
    assert _rolling_options(Args).profile.items == 1024
    Args.onboard = "watch"
    with pytest.raises(InputError, match="--profile"):
        _rolling_options(Args)
    argv = ["monitor", "--connect", "udpin://:1", "--fences", str(tmp_path / "f.geojson")]
    code = main([*argv, "--profile", "plane"])
    assert code == 2
    assert "--onboard rolling" in capsys.readouterr().err


def test_the_rolling_fence_compiles_for_the_vehicles_autopilot():
    from types import SimpleNamespace

    from alphafence.monitor.rolling import RollingFence

    def rolling(autopilot, profile):
        vehicle = SimpleNamespace(autopilot=autopilot)
        options = RollingOptions(profile=profile)
        return RollingFence(vehicle, FenceSet(squares([(0.0, 0.0)])), options, BRAKING, print, None)

    assert rolling("px4", None).profile.name == "px4"
    assert rolling("ardupilot", None).profile.name == "copter"
    assert rolling("px4", PROFILES["px4-constrained"]).profile.items == 16
    with pytest.raises(
        InputError, match="copter is ArduPilot's fence storage, and the vehicle runs PX4"
    ):
        rolling("px4", PROFILES["copter"])
