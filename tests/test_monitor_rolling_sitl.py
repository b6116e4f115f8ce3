"""Test (c) of issue 11: a rolling onboard fence in a real flight (copter SITL, Malta).

The Malta fences are built from the shared extract (``alphafence build``, alpha, default
rules). SITL starts at the east end of a 3 km leg due west across the Grand Harbour's
neighbourhoods (from 35.89042 N 14.53959 E to 35.88964 N 14.50638 E) that passes more than a
dozen keep-out fences but no keep-out fence on the way (the test checks both). The monitor runs
with ``--onboard rolling`` and the default copter profile (70 items, 560 bytes), as
``alphafence monitor --onboard rolling`` runs it, on the test's own connection; once it
has uploaded the first fence, the ``copter-rtl`` fence parameters are set (ArduPilot enforces
the rolling fence: RTL on a breach), and the copter takes off and flies the leg in GUIDED at
10 m/s.

Reach: 10 m/s for 30 s plus the 37 m stopping distance, 337 m. At speedup 5 a wall second is
five of the vehicle's, so the upload budget is 15 s of flight (3 s wall, for the compile, the
upload and its read-back). The test asserts that at every position logged after the first
upload, the fence in force (the last one written; during a re-upload, the old one and the new
one both) contains every full-resolution keep-out fence within reach (each fence in force
is the one the monitor downloaded from the vehicle after its upload), that every re-upload
was verified, that there were re-uploads, and that ArduPilot reported no breach.

Measured (speedup 5): see the test's printout and the README's rolling paragraph.
"""

from __future__ import annotations

import asyncio
import math
import statistics
import time

import numpy as np
import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import Braking
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.storage import PROFILES
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.observe import Observer
from alphafence.monitor.options import RollingOptions
from alphafence.monitor.runner import Monitor
from alphafence.vehicle.link import open_vehicle
from tests.sitl_flight import (
    ALTITUDE,
    FlightLog,
    ask_fence_status,
    speedup_options,
    take_off,
    until,
    unwatch,
    watch,
    within,
)

pytestmark = pytest.mark.sitl

START = (14.53959, 35.89042)  # lon, lat: the east end of the leg (SITL's home)
END = (14.50638, 35.88964)  # the west end, 3.0 km away
SPEEDUP = 5
SPEED = 10.0
ROLLING = RollingOptions(profile=PROFILES["copter"], speed_mps=SPEED, upload_budget_s=15.0)
REACH = ROLLING.reach_m(Braking())
CLEAR_M = 50.0  # the leg keeps this far from every keep-out fence
ARRIVED_M = 15.0
TOLERANCE_M = 0.05  # MAVLink's 1e-7 degrees, and the decoded circles' polygons
WALL_TIMEOUT = 240.0


@pytest.fixture(scope="module")
def malta_fences(malta, tmp_path_factory):
    from alphafence.cli import main

    out = tmp_path_factory.mktemp("malta-rolling") / "fences.geojson"
    assert main(["build", str(malta), "-o", str(out)]) == 0
    return out


class Layers(Observer):
    """The onboard layer the monitor loads after each of its uploads (downloaded from the
    vehicle), in order."""

    def __init__(self):
        self.monitor = None
        self.loaded = []  # (time, OnboardLayer)

    def on_event(self, event):
        if event["event"] == "onboard_fence" and event.get("cause") == "rolling":
            self.loaded.append((event["time"], self.monitor.engine.onboard))


def exclusions(layer):
    idx = layer.index
    return shapely.union_all(
        [idx.local[j] for j in range(len(idx.records)) if idx.records[j].kind == "keep_out"]
    )


async def test_the_rolling_fence_holds_every_fence_within_reach_along_a_malta_leg(
    malta_fences, sitl_factory
):
    from alphafence.vehicle.params import PROFILES as PARAMS
    from alphafence.vehicle.params import apply_params

    frame = LocalFrame(*START)  # metres east and north of SITL's home
    records = read_fences(malta_fences)
    fences = FenceSet(records, frame=frame)
    keep_out = np.flatnonzero(fences.kind == 0)
    ex, ey = (float(v) for v in frame.to_local(*END))
    leg = shapely.LineString([(0.0, 0.0), (ex, ey)])
    gap = float(shapely.distance(leg, fences.local[keep_out]).min())
    assert gap >= CLEAR_M, f"a keep-out fence {gap:.0f} m from the leg"
    near_leg = int((shapely.distance(leg, fences.local[keep_out]) <= REACH).sum())
    assert near_leg >= 10, near_leg

    sitl = await sitl_factory(home=f"{START[1]},{START[0]},80,270", speedup=SPEEDUP)
    log = FlightLog(frame)
    monitor_log = EventLog()
    log.events = monitor_log.events
    layers = Layers()
    results = {}

    async def flight():
        async with open_vehicle(sitl.connection_url) as vehicle:
            log.texts = vehicle.texts
            watchers = watch(log, vehicle, "positions", "speeds", "modes", "fence")
            options = speedup_options(SPEEDUP, onboard="rolling", rolling=ROLLING)
            monitor = Monitor(vehicle, fences, options, monitor_log, observers=[layers])
            layers.monitor = monitor
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            try:
                await vehicle.telemetry.set_rate_position(10.0)
                await vehicle.telemetry.set_rate_velocity_ned(10.0)
                await until("the first rolling fence", lambda: layers.loaded, 60, log)
                params = await apply_params(vehicle, PARAMS["copter-rtl"])
                assert params.values["FENCE_ENABLE"] == 1
                await ask_fence_status(vehicle, 2.0)
                await until("a FENCE_STATUS", lambda: log.fence, 15, log)
                await take_off(vehicle.action, log)
                await vehicle.action.set_current_speed(SPEED)
                await vehicle.action.goto_location(END[1], END[0], sitl.home.alt + ALTITUDE, 0.0)
                results["t_goto"] = time.monotonic()

                def arrived():
                    _, x, y, _ = log.positions[-1]
                    return math.hypot(x - ex, y - ey) < ARRIVED_M

                results["t_end"] = await until("the end of the leg", arrived, 150, log)
                assert not task.done(), "the monitor stopped by itself"
                results["checks"] = monitor.engine.checks
            finally:
                stop.set()
                await asyncio.wait_for(asyncio.gather(task, return_exceptions=True), 10)
                await unwatch(watchers)

    await within(flight(), WALL_TIMEOUT, log)
    events = list(log.events)
    uploads = [e for e in events if e["event"] == "onboard_upload"]
    kept = [e for e in events if e["event"] == "onboard_kept"]
    bad = [e for e in events if e["event"] in ("onboard_upload_failed", "onboard_behind")]
    assert not bad, bad
    assert uploads and all(u["verified"] is True for u in uploads), uploads
    assert len(uploads) >= 3, uploads  # it rolled: the fences along the leg change
    assert len(layers.loaded) == len(uploads)
    assert all(u["items"] <= 70 and u["bytes"] <= 560 for u in uploads), uploads

    # the fence in force at each position: the last written (from the end of its upload),
    # and during a re-upload the new one too (ArduPilot writes it when the last item arrives)
    timeline = [
        (u["started"], u["time"], exclusions(layer))
        for u, (_, layer) in zip(uploads, layers.loaded)
    ]
    prepared = [shapely.buffer(g, TOLERANCE_M) for _, _, g in timeline]
    for g in prepared:
        shapely.prepare(g)
    flown = [p for p in log.positions if p[0] >= timeline[0][1]]
    assert len(flown) >= 200, len(flown)
    checked, reached = 0, set()
    for t, x, y, _ in flown:
        current = max(k for k, (_, done, _) in enumerate(timeline) if done <= t)
        in_force = [current]
        if current + 1 < len(timeline) and timeline[current + 1][0] <= t:
            in_force.append(current + 1)  # being uploaded: either may be the vehicle's
        for i in fences.tree.query(shapely.Point(x, y), predicate="dwithin", distance=REACH):
            if fences.kind[i] != 0:
                continue
            reached.add(records[i].site_id)
            for k in in_force:
                assert shapely.covers(prepared[k], fences.local[i]), (
                    f"at x={x:.0f} y={y:.0f} (t={t:.2f}) the fence in force (upload {k}) does "
                    f"not contain {records[i].site_id}"
                )
                checked += 1
    assert checked > 0 and len(reached) >= 5, (checked, reached)

    # ArduPilot enforced the rolling fence and was never in breach; no RTL
    assert log.fence and all(f["breach_status"] == 0 for _, f in log.fence), log.summary()
    assert "RTL" not in [m for _, m in log.modes], log.summary()
    assert not [t for t, s in log.texts if "fence breached" in s.lower()], log.summary()

    seconds = [u["seconds"] for u in uploads[1:]] or [uploads[0]["seconds"]]
    print(
        f"\nleg 3.0 km, {near_leg} keep-out fences within reach of it, {len(reached)} reached; "
        f"{len(uploads)} uploads ({len(kept)} compiles unchanged, nothing sent), items "
        f"{[u['items'] for u in uploads]}, bytes {[u['bytes'] for u in uploads]}, merges "
        f"{[u['merges'] for u in uploads]}; compile {max(u['compile_s'] for u in uploads):.2f} s "
        f"at most; compile + upload + read-back median {statistics.median(seconds):.2f} s, max "
        f"{max(seconds):.2f} s wall (speedup {SPEEDUP}); {len(flown)} positions, {checked} "
        f"containment checks, all held; {results['checks']} monitor checks; flight "
        f"{results['t_end'] - results['t_goto']:.1f} s wall"
    )


# -- what the vehicle holds during a re-upload -------------------------------------------

PAUSE_AT = 35  # of 69 items: the upload stops here for PAUSE_S (ArduPilot waits 8 s)
PAUSE_S = 4.0


def _exclusion(frame, xy):
    """(command, vertex count, lat e7, lon e7) of one exclusion polygon at metric ``xy``."""
    from alphafence.geo.coords import to_e7
    from alphafence.mavlink import ids

    lon, lat = frame.to_wgs84(np.array([p[0] for p in xy]), np.array([p[1] for p in xy]))
    cmd = ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
    return [(cmd, len(xy), to_e7(b), to_e7(a)) for a, b in zip(lon, lat)]


class RawLink:
    """A pymavlink link to SITL that uploads fences item by item (and can stop halfway) and
    keeps every FENCE_STATUS with its arrival time."""

    def __init__(self, url):
        from pymavlink import mavutil

        self.c = mavutil.mavlink_connection(url, source_system=255, dialect="ardupilotmega")
        assert self.c.wait_heartbeat(timeout=30) is not None
        self.status = []  # (time, breach_status)

    def pump(self, done, timeout):
        """Read messages until ``done(message)`` (returned) or ``timeout`` (None)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            m = self.c.recv_match(blocking=True, timeout=0.1)
            if m is None:
                continue
            if m.get_type() == "FENCE_STATUS":
                self.status.append((time.monotonic(), m.breach_status))
            if done(m):
                return m
        return None

    def upload(self, items, pause_at=None):
        """Upload, answering each request; before sending item ``pause_at``, wait PAUSE_S.
        Returns (MAV_MISSION_RESULT, {"pause", "resume", "last", "ack": times})."""
        from alphafence.mavlink import ids

        fence = ids.MAV_MISSION_TYPE_FENCE
        self.c.mav.mission_count_send(1, 1, len(items), fence)
        marks, answered = {}, 0
        kinds = ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
        while True:
            m = self.pump(lambda m: m.get_type() in kinds and m.mission_type == fence, 10)
            assert m is not None, "the vehicle stopped asking for items"
            if m.get_type() == "MISSION_ACK":
                if m.type == ids.MAV_MISSION_INVALID_SEQUENCE and "last" not in marks:
                    continue  # a stale re-request answered twice: ArduPilot keeps the transfer
                marks["ack"] = time.monotonic()
                return m.type, marks
            if m.seq < answered:  # a re-request from before the pause, already answered
                continue
            if m.seq == pause_at and "pause" not in marks:
                marks["pause"] = time.monotonic()
                self.pump(lambda m: False, PAUSE_S)
                marks["resume"] = time.monotonic()
            answered = m.seq
            cmd, n, lat, lon = items[m.seq]
            if m.seq == len(items) - 1:
                marks["last"] = time.monotonic()
            self.c.mav.mission_item_int_send(
                1, 1, m.seq, 0, cmd, 0, 1, n, 0, 0, 0, lat, lon, 0, fence
            )


def _hold_during_upload(url):
    from pymavlink.dialects.v20 import ardupilotmega as mav

    from alphafence.mavlink import ids

    frame = LocalFrame(*START)
    old = _exclusion(frame, [(-100, -100), (100, -100), (100, 100), (-100, 100)])  # home in it
    ring = np.linspace(0, 2 * math.pi, 69, endpoint=False)
    new = _exclusion(frame, [(300 * math.cos(a), -1100 + 300 * math.sin(a)) for a in ring])
    link = RawLink(url)
    for name, value in (("FENCE_TYPE", 4), ("FENCE_ACTION", 0), ("FENCE_ENABLE", 1)):
        link.c.mav.param_set_send(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_INT8)
        assert link.pump(lambda m, n=name: m.get_type() == "PARAM_VALUE" and m.param_id == n, 5)
    link.c.mav.command_long_send(
        1, 1, ids.MAV_CMD_SET_MESSAGE_INTERVAL, 0, ids.MAVLINK_MSG_ID_FENCE_STATUS, 50_000,
        0, 0, 0, 0, 0,
    )  # fmt: skip
    result, _ = link.upload(old)
    assert result == mav.MAV_MISSION_ACCEPTED
    assert link.pump(lambda m: link.status and link.status[-1][1] == 1, 10), "no breach at home"
    result, marks = link.upload(new, pause_at=PAUSE_AT)
    assert result == mav.MAV_MISSION_ACCEPTED
    assert link.pump(lambda m: link.status[-1][1] == 0, 5), "the new fence never took over"
    return link.status, marks


async def test_the_vehicle_keeps_its_fence_until_the_last_item_of_a_re_upload(sitl_factory):
    """Home inside the old fence's exclusion square (FENCE_STATUS: breach); a re-upload of a
    69-item fence far away stops for 4 s after 35 items: the old fence stays in force (every
    FENCE_STATUS meanwhile a breach), and the new one takes over when the last item arrives
    (within ten FENCE_STATUS reports after the ACK, half a second of the vehicle's time)."""
    sitl = await sitl_factory(home=f"{START[1]},{START[0]},80,0", speedup=1)
    status, marks = await asyncio.wait_for(
        asyncio.to_thread(_hold_during_upload, sitl.pymavlink_url), 90
    )
    during = [b for t, b in status if marks["pause"] <= t <= marks["last"]]
    assert len(during) >= 10 and set(during) == {1}, during  # the old fence, all along
    # counted in the vehicle's own reports (20 a second of its clock), not in wall time: the
    # new fence holds within ten reports after the ACK (half a second of the vehicle's time;
    # a few may have been sent before it), and from then on
    after = [b for t, b in status if t >= marks["ack"]]
    assert 0 in after[:10] and set(after[after.index(0) :]) == {0}, after
    first_clear = next(t for t, b in status if t >= marks["last"] and b == 0)
    print(
        f"\n{len(during)} FENCE_STATUS during the re-upload ({PAUSE_S:g} s stopped after "
        f"{PAUSE_AT} of 69 items), all breach (the old fence); the ACK {1e3 * (marks['ack'] - marks['last']):.0f} ms "
        f"after the last item, the first status of the new fence {1e3 * (first_clear - marks['last']):.0f} ms after it"
    )
