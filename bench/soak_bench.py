"""Soak target: the monitor against SITL for 30 minutes at speedup 10 with simulated ADS-B
traffic: no check missed, no unhandled exception, memory growth under 20 MB.

``python -m bench --osm MALTA.osm.pbf --only soak [--soak-minutes N]`` (``make soak``: 30 min).

Setup. ArduPilot copter SITL at ``malta_airport`` (300 m north of the airport boundary), speedup
10, with SITL's simulated ADS-B receiver on (``SIM_ADSB_*``, ``ADSB_TYPE`` 0: the ADSB_VEHICLE
messages are forwarded to our link; see tests/test_monitor_adsb_sitl.py): 3 aircraft spawned
around the vehicle (300 m spread) at the vehicle's cruise altitude, climbing about 3 m/s, so
conflicts open and clear all the time. The fences are all of Malta's, built from the OSM file as
bench/monitor_cpu_bench.py does. The real :class:`alphafence.monitor.runner.Monitor` runs the whole
time on the bench's MAVSDK connection, with an ``EventLog`` appending to a temporary file
(as ``alphafence monitor --log`` does), at ``rate_hz`` 10, alert only (no enforce). Its options
are the speedup-scaled ones of the SITL tests (tests/sitl_flight.py ``speedup_options``): the
engine's durations are wall seconds while speeds are the vehicle's, so ``hold_s``,
``backoff_s`` and ``stale_s`` are divided by the speedup and ``max_speed_mps`` multiplied by
it (unscaled, the copter's 10 m/s is 100 m/s per wall second: a "GPS glitch").

Meanwhile the copter flies: arm, take off in GUIDED to 30 m, then GUIDED gotos at 10 m/s round
a loop of legs (``LEGS``) through the aerodrome's warning layer and keep-out, a hospital's and
a substation's keep-outs and a stadium/school warning layer, and back over home, for ever
(about 3.2 km, 30 s wall a lap). ArduPilot's own fence is off (the kit's SITL parameters), so
nothing stops it. If the copter is found disarmed (landed, crashed, failsafe) it is put back in
GUIDED, re-armed and launched again; that is counted and reported.

What "no check missed" means here. At speedup 10 the 10 Hz position stream arrives at 100 Hz
wall. Every new position schedules one check (a callback on the event loop) of the *latest*
position: positions arriving within one turn of the loop are coalesced into a single check, by
design. So a position is never checked "late" by being queued; it is covered by
the next check of the same or a newer position. The bench watches the monitor through its
public observer hook (:mod:`alphafence.monitor.observe`): every position the position feed
delivers, with its arrival time, and every engine step, with the time it began. The target is:
**every position is covered by a check (of it or a newer position) within 0.1 s wall** (1 s of flight at speedup 10), i.e. the
longest wait from a position's arrival to the next check, over the whole soak, is < 0.1 s, and
no position is left uncovered at the end. It also reports positions per check (the coalescing),
the longest gap between consecutive checks, and the longest gap between arriving positions
(a gap between checks that follows a gap in telemetry is the link's, not the monitor's).
Engine steps that stop at the GPS glitch / no-fix test do no fence check; they are counted
separately.

"No unhandled exception": a loop exception handler records anything asyncio reports (for
example "Task exception was never retrieved"); the Monitor's own tasks (one per feed: telemetry,
ADS-B) and its run() task are inspected every minute and at the end for a task that died with an
exception (run() swallows those when it stops); and the event log's handled-error events
(``action_failed``, ``alert_failed``, ``adsb_unavailable``, ``traffic_link_unavailable``) are
reported next to it. Target: zero unhandled.

Memory: this process's RSS (``VmRSS`` in /proc/self/status; MAVSDK runs in-process) every
30 s; growth is the end value minus the value after a 2-minute warm-up (a quarter of the run,
for runs shorter than 8 minutes). Target: < 20 MB. The peak is reported too.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import sys
import tempfile
import time
from collections import Counter

from alphafence.mavlink import ids
from alphafence.sitl.find import find_sitl_binary

SPEEDUP = 10
HOME = "malta_airport"
ALTITUDE = 30.0  # m above home
SPEED = 10.0  # m/s (the vehicle's)
RATE_HZ = 10.0  # the monitor's telemetry rate (vehicle time: 100 Hz wall at speedup 10)
HOME_ALT_AMSL = 80.0  # malta_airport, kit/alphafence/data/sitl/homes.toml
ADSB_PARAMS = {
    "SIM_ADSB_COUNT": 3,  # simulated aircraft (>= 0 also makes SERIAL1 the simulated receiver)
    "SIM_ADSB_RADIUS": 300,  # m, spawn spread and respawn distance from the vehicle
    "SIM_ADSB_ALT": HOME_ALT_AMSL + ALTITUDE,  # m, reported (AMSL) altitude at spawn
    "SIM_ADSB_TYPES": 1,  # the MAVLink "shortcut" receiver
    "ADSB_TYPE": 0,  # ArduPilot's ADS-B library off: ADSB_VEHICLE forwarded to the GCS link
}
# the loop, metres east / north of home (Malta fences near malta_airport, from the OSM build)
LEGS = (
    (0.0, -400.0),  # south: the aerodrome's warning layer (~180 m) and keep-out (~210 m)
    (480.0, 70.0),  # a hospital's keep-out (420..542 E, 11..133 N)
    (500.0, 570.0),  # a substation's keep-out (463..534 E, 533..602 N)
    (-430.0, 460.0),  # a stadium's and a school's warning layers
    (0.0, 0.0),  # home
)
ARRIVED_M = 15.0
LATE_S = 0.1  # a position must be covered by a check within this (wall)
WARMUP_S = 120.0
RSS_EVERY_S = 30.0
PROGRESS_S = 60.0
MAX_GROWTH_MB = 20.0
HANDLED_ERRORS = ("action_failed", "alert_failed", "adsb_unavailable", "traffic_link_unavailable")


def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return math.nan


def _options(speedup: float):
    """MonitorOptions scaled for SITL at ``speedup`` (as tests/sitl_flight.speedup_options)."""
    from alphafence.monitor.options import MonitorOptions

    o = MonitorOptions(enforce=False)
    o.hold_s /= speedup
    o.backoff_s /= speedup
    o.stale_s /= speedup
    o.max_speed_mps *= speedup
    return o


class _Stats:
    """Positions arriving and checks done, on the wall clock (time.monotonic())."""

    def __init__(self):
        self.positions = 0
        self.steps = 0  # engine.step calls
        self.checks = 0  # of which did a fence check
        self.uncovered_since = None  # arrival of the oldest position no step has covered
        self.last_position = None
        self.last_check = None
        self.max_wait = 0.0  # arrival -> the step covering it
        self.max_wait_at = None
        self.late = 0  # steps that came more than LATE_S after a position they cover
        self.max_check_gap = 0.0
        self.max_position_gap = 0.0
        self.max_batch = 0
        self.batch = 0

    def position(self, now):
        """A position arrived at ``now``."""
        if self.last_position is not None:
            self.max_position_gap = max(self.max_position_gap, now - self.last_position)
        self.last_position = now
        self.positions += 1
        self.batch += 1
        if self.uncovered_since is None:
            self.uncovered_since = now

    def step(self, now, checked):
        """An engine step began at ``now``; ``checked``: it did a fence check."""
        self.steps += 1
        if self.uncovered_since is not None:
            wait = now - self.uncovered_since
            if wait > self.max_wait:
                self.max_wait, self.max_wait_at = wait, now
            self.late += wait > LATE_S
            self.uncovered_since = None
        self.max_batch = max(self.max_batch, self.batch)
        self.batch = 0
        if checked:
            self.checks += 1
            if self.last_check is not None:
                self.max_check_gap = max(self.max_check_gap, now - self.last_check)
            self.last_check = now

    def uncovered_age(self):
        return 0.0 if self.uncovered_since is None else time.monotonic() - self.uncovered_since


def _soak_observer(stats: _Stats):
    """An observer of the real Monitor that counts every position it receives and times every
    engine step (the monitor itself unchanged)."""
    from alphafence.monitor.observe import Observer

    class SoakObserver(Observer):
        def on_value(self, stream, t, value):
            if stream == "position":
                stats.position(t)

        def on_step(self, step):
            stats.step(step.started, step.checked)

    return SoakObserver()


async def _command(direct, command, *params):
    from alphafence.monitor.commands import command_long

    ack = await command_long(direct, 1, command, *params)
    return json.loads(ack.fields_json or "{}").get("result")


class _Soak:
    def __init__(self, sitl, vehicle, fences, minutes, console):
        self.sitl = sitl
        self.vehicle = vehicle
        self.fences = fences
        self.seconds = 60.0 * minutes
        self.warmup_s = min(WARMUP_S, self.seconds / 4)
        self.console = console
        self.stats = _Stats()
        self.loop_errors = []  # what asyncio's exception handler was given
        self.dead_tasks = {}  # Monitor task -> the exception it died with
        self.flight_errors = []  # the bench's own flying (not the monitor's)
        self.incidents = []  # disarmed / relaunched mid-soak
        self.launches = 0
        self.modes = Counter()  # flight modes seen while flying the legs (polls)
        self.legs = 0
        self.leg_timeouts = 0
        self.rss = []  # (wall s since start, MB)
        self.rss_warm = None
        self.boot_ms = []  # (monotonic, SYSTEM_TIME time_boot_ms)
        from alphafence.geo.frame import LocalFrame

        self.frame = LocalFrame(sitl.home.lon, sitl.home.lat)

    # -- helpers -------------------------------------------------------------------
    def _latest(self, key):
        item = self.monitor.latest.get(key)
        return item[1] if item else None

    def _elapsed(self):
        return time.monotonic() - self.t0

    def _check_tasks(self):
        tasks = list(self.monitor.tasks) + [self.monitor_task]
        for t in tasks:
            if t.done() and not t.cancelled() and t not in self.dead_tasks:
                exc = t.exception()
                if exc is not None:
                    self.dead_tasks[t] = exc
                elif t is self.monitor_task or t in self.monitor.tasks:
                    # a follower whose stream ended, or run() returning before stop: dead too
                    self.dead_tasks[t] = RuntimeError(f"task {t.get_name()} ended")

    def _on_loop_error(self, loop, context):
        self.loop_errors.append(context.get("message", "") + f" {context.get('exception')!r}")
        loop.default_exception_handler(context)

    # -- the run ---------------------------------------------------------------------
    async def run(self):
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        from alphafence.monitor.eventlog import EventLog
        from alphafence.monitor.runner import Monitor

        loop = asyncio.get_running_loop()
        loop.set_exception_handler(self._on_loop_error)
        self.direct = MavlinkDirectAsync(self.vehicle.system)
        with tempfile.TemporaryDirectory(prefix="alphafence-soak-") as tmp:
            self.log_path = os.path.join(tmp, "events.jsonl")
            self.log = EventLog(self.log_path)
            self.monitor = Monitor(
                self.vehicle,
                self.fences,
                _options(self.sitl.speedup),
                self.log,
                rate_hz=RATE_HZ,
                observers=[_soak_observer(self.stats)],
            )
            stop = asyncio.Event()
            self.t0 = time.monotonic()
            self.monitor_task = asyncio.create_task(self.monitor.run(stop), name="monitor.run")
            helpers = [
                asyncio.create_task(c())
                for c in (self._sim_clock, self._sample_rss, self._progress)
            ]
            flight = asyncio.create_task(self._fly())
            try:
                await asyncio.sleep(self.seconds)
            finally:
                self.wall_s = self._elapsed()
                self.rss_end = _rss_mb()
                self.rss.append((self.wall_s, self.rss_end))
                self._check_tasks()
                self.uncovered_at_end = self.stats.uncovered_age()
                self.positions_flowing = (
                    self.stats.last_position is not None
                    and time.monotonic() - self.stats.last_position < 1.0
                )
                for t in [flight, *helpers]:
                    t.cancel()
                await asyncio.gather(flight, *helpers, return_exceptions=True)
                stop.set()
                try:
                    await asyncio.wait_for(self.monitor_task, 10.0)
                except asyncio.TimeoutError:
                    self.dead_tasks[self.monitor_task] = RuntimeError("run() did not stop in 10 s")
                except Exception as exc:
                    self.dead_tasks.setdefault(self.monitor_task, exc)
                await self.log.close()
                with open(self.log_path, encoding="utf-8") as fh:
                    self.log_lines = sum(1 for _ in fh)
                loop.set_exception_handler(None)
        return self

    async def _sim_clock(self):
        """SYSTEM_TIME at 1 Hz of vehicle time: how many flight minutes the soak covered."""
        with contextlib.suppress(Exception):
            await _command(
                self.direct, ids.MAV_CMD_SET_MESSAGE_INTERVAL, ids.MAVLINK_MSG_ID_SYSTEM_TIME, 1e6
            )
        async for message in self.direct.subscribe_message("SYSTEM_TIME"):
            ms = json.loads(message.fields_json)["time_boot_ms"]
            if len(self.boot_ms) < 2:
                self.boot_ms.append((time.monotonic(), ms))
            else:
                self.boot_ms[1] = (time.monotonic(), ms)

    def sim_minutes(self):
        if len(self.boot_ms) < 2:
            return math.nan
        (w0, b0), (w1, b1) = self.boot_ms
        # extrapolate the first sample back to the soak's start at the measured rate
        rate = (b1 - b0) / 1000.0 / max(w1 - w0, 1e-9)
        return ((b1 - b0) / 1000.0 + (w0 - self.t0) * rate) / 60.0

    async def _sample_rss(self):
        while True:
            elapsed, mb = self._elapsed(), _rss_mb()
            self.rss.append((elapsed, mb))
            if self.rss_warm is None and elapsed >= self.warmup_s:
                self.rss_warm = mb
            wait = RSS_EVERY_S - elapsed % RSS_EVERY_S
            if self.rss_warm is None:
                wait = min(wait, max(0.05, self.warmup_s - elapsed))
            await asyncio.sleep(wait)

    async def _progress(self):
        while True:
            await asyncio.sleep(PROGRESS_S)
            self._check_tasks()
            s, ev = self.stats, Counter(e["event"] for e in self.log.events)
            wall = self._elapsed()
            pos = self._latest("position")
            where = (
                f"alt {pos.relative_altitude_m:5.1f} m, {self.monitor.engine.sm.level.name}"
                if pos
                else "no position"
            )
            self.console.print(
                f"[dim]soak[/] {wall / 60:5.1f} min wall, {self.sim_minutes():6.1f} min flight | "
                f"checks {s.checks} ({s.checks / wall:.0f}/s), {s.positions / max(s.checks, 1):.2f} "
                f"positions/check, longest wait {1000 * s.max_wait:.0f} ms | "
                f"levels {ev['level']}, conflicts {ev['traffic_conflict']} | "
                f"RSS {_rss_mb():.1f} MB | laps {self.legs / len(LEGS):.1f}, launches "
                f"{self.launches} | unhandled {len(self.loop_errors) + len(self.dead_tasks)} | "
                f"{where}",
                soft_wrap=True,
            )

    # -- flying ----------------------------------------------------------------------
    async def _fly(self):
        from mavsdk.plugins.action import ActionError

        leg = 0
        while True:
            try:
                if self._latest("armed") is not True or self._on_ground():
                    if self.launches:
                        self.incidents.append(
                            f"{self._elapsed() / 60:.1f} min: found "
                            f"{'disarmed' if self._latest('armed') is False else 'on the ground'}"
                            f" in {self._mode()}, relaunched"
                        )
                    await self._launch()
                x, y = LEGS[leg % len(LEGS)]
                await self._goto(x, y)
                leg += 1
                self.legs += 1
            except asyncio.CancelledError:
                raise
            except (ActionError, asyncio.TimeoutError, RuntimeError) as exc:
                self.flight_errors.append(f"{self._elapsed() / 60:.1f} min: {exc!r}")
                await asyncio.sleep(2.0)

    def _mode(self):
        mode = self._latest("mode")
        return mode.name if mode is not None else "no mode"

    def _on_ground(self):
        pos = self._latest("position")
        return pos is None or pos.relative_altitude_m < 2.0

    async def _wait(self, what, predicate, timeout):
        deadline = time.monotonic() + timeout
        while not predicate():
            self.modes[self._mode()] += 1
            if time.monotonic() > deadline:
                raise asyncio.TimeoutError(f"{what}: not within {timeout:g} s wall")
            await asyncio.sleep(0.05)

    async def _launch(self):
        from mavsdk.plugins.action import ActionError

        action = self.vehicle.action
        await self._wait("telemetry", lambda: self._latest("position") is not None, 30)
        # after a landing ArduCopter is left in LAND, which refuses arming: GUIDED first
        with contextlib.suppress(Exception):
            await _command(
                self.direct,
                ids.MAV_CMD_DO_SET_MODE,
                ids.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                ids.COPTER_MODE_GUIDED,
            )
        await action.set_takeoff_altitude(ALTITUDE)
        deadline = time.monotonic() + 60.0
        while True:
            try:
                if self._latest("armed") is not True:
                    await action.arm()
                await action.takeoff()
                break
            except ActionError:  # pre-arm checks not passed yet
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(1.0)
        self.launches += 1
        await self._wait(
            "climb to 90 % of the takeoff altitude",
            lambda: self._latest("position").relative_altitude_m >= 0.9 * ALTITUDE,
            60,
        )
        await action.set_current_speed(SPEED)

    async def _goto(self, x, y):
        lon, lat = self.frame.to_wgs84(x, y)
        pos = self._latest("position")
        px, py = self.frame.to_local(pos.longitude_deg, pos.latitude_deg)
        distance = math.hypot(x - float(px), y - float(py))
        await self.vehicle.action.goto_location(
            float(lat), float(lon), self.sitl.home.alt + ALTITUDE, 0.0
        )

        def arrived():
            p = self._latest("position")
            if self._latest("armed") is False:
                return True  # the main loop relaunches
            px, py = self.frame.to_local(p.longitude_deg, p.latitude_deg)
            return math.hypot(x - float(px), y - float(py)) < ARRIVED_M

        timeout = (2.0 * distance / SPEED + 30.0) / self.sitl.speedup + 10.0
        try:
            await self._wait("leg", arrived, timeout)
        except asyncio.TimeoutError:
            self.leg_timeouts += 1


async def _soak(osm, minutes, console):
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.fencing.pipeline import BuildOptions, build_fences
    from alphafence.sitl import launch_sitl
    from alphafence.vehicle.link import open_vehicle
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    rules = load_rules()
    result = build_fences(read_database([osm], rules).features, rules, BuildOptions())
    fences = FenceSet(
        [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    )
    console.print(
        f"soak: {minutes:g} min wall, SITL {HOME} x{SPEEDUP} with {ADSB_PARAMS['SIM_ADSB_COUNT']} "
        f"simulated ADS-B aircraft, {len(fences.records)} Malta fences; progress every minute"
    )
    async with launch_sitl(
        home=HOME, speedup=SPEEDUP, param_values=ADSB_PARAMS, ready_timeout=120.0
    ) as sitl:
        async with open_vehicle(sitl.connection_url, timeout=30.0) as vehicle:
            soak = await _Soak(sitl, vehicle, fences, minutes, console).run()
            soak.sitl_alive = sitl.running
    return soak, len(fences.records)


def _event_bytes(events) -> float:
    """Roughly what the EventLog's in-memory event list holds (dicts, keys shared)."""
    total = sys.getsizeof(events)
    for e in events:
        total += sys.getsizeof(e) + sum(sys.getsizeof(v) for v in e.values())
    return total / 2**20


def run(osm, Row, minutes=30.0, console=None):
    if find_sitl_binary() is None:
        return [
            Row(
                "soak: monitor on SITL x10 with ADS-B",
                "skipped: no SITL binary",
                "no missed check, 0 exceptions, < 20 MB",
                "-",
                "-",
                True,
            )
        ]
    from rich.console import Console

    console = console or Console(width=150)
    soak, n_fences = asyncio.run(_soak(osm, minutes, console))
    s = soak.stats
    events = list(soak.log.events)
    kinds = Counter(e["event"] for e in events)
    levels = Counter(e["level"] for e in events if e["event"] == "level")
    conflicts = [e for e in events if e["event"] == "traffic_conflict"]
    wall_min, sim_min = soak.wall_s / 60.0, soak.sim_minutes()

    no_miss = (
        s.max_wait < LATE_S
        and soak.uncovered_at_end < LATE_S
        and soak.positions_flowing
        and s.checks > 0
    )
    unhandled = len(soak.loop_errors) + len(soak.dead_tasks)
    handled = ", ".join(f"{k} {kinds[k]}" for k in HANDLED_ERRORS)
    growth = soak.rss_end - soak.rss_warm if soak.rss_warm is not None else math.nan
    rss_max = max(mb for _, mb in soak.rss)
    ran_through = (
        soak.wall_s >= 0.99 * 60 * minutes and soak.sitl_alive and not soak.monitor_task.cancelled()
    )
    exercised = levels and conflicts and soak.legs >= len(LEGS)

    rows = [
        Row(
            f"soak: monitor on SITL x{SPEEDUP} with ADS-B, {n_fences} Malta fences",
            f"{wall_min:.1f} min wall = {sim_min:.1f} min flight",
            f"{minutes:g} min",
            f"{soak.legs} legs ({soak.legs / len(LEGS):.1f} laps, {soak.leg_timeouts} timed out), "
            f"{soak.launches} launch(es); modes seen {', '.join(sorted(soak.modes))}"
            + (f"; {'; '.join(soak.incidents)}" if soak.incidents else "")
            + (
                f"; bench flight errors: {'; '.join(soak.flight_errors)}"
                if soak.flight_errors
                else ""
            ),
            f"x{60 * sim_min / soak.wall_s:.1f}" if math.isfinite(sim_min) else "-",
            bool(ran_through and exercised and not soak.flight_errors),
        ),
        Row(
            "soak: positions vs checks",
            f"{s.positions} positions, {s.checks} checks ({s.positions / max(s.checks, 1):.2f} "
            f"positions/check, max {s.max_batch}); {s.checks / soak.wall_s:.0f} checks/s; "
            f"{s.steps - s.checks} steps without a fence check (glitch/no fix)",
            f"every position checked < {1000 * LATE_S:.0f} ms wall",
            f"longest wait {1000 * s.max_wait:.0f} ms ({s.late} > {1000 * LATE_S:.0f} ms); "
            f"longest gap between checks {1000 * s.max_check_gap:.0f} ms, between positions "
            f"{1000 * s.max_position_gap:.0f} ms",
            "-",
            no_miss,
        ),
        Row(
            "soak: events",
            ", ".join(f"{k} {v}" for k, v in kinds.most_common()),
            "level changes and conflicts happen",
            "levels "
            + ", ".join(f"{k} {v}" for k, v in sorted(levels.items()))
            + f"; {len({e['aircraft'] for e in conflicts})} aircraft in conflict; "
            f"log file {soak.log_lines} lines",
            "-",
            bool(exercised and soak.log_lines == len(events)),
        ),
        Row(
            "soak: unhandled exceptions",
            str(unhandled)
            + "".join(f"; {m}" for m in soak.loop_errors[:3])
            + "".join(f"; {t.get_name()}: {e!r}" for t, e in soak.dead_tasks.items()),
            "0",
            f"handled: {handled}",
            "-",
            unhandled == 0,
        ),
        Row(
            "soak: memory (RSS) growth after warm-up",
            f"{growth:+.1f} MB ({soak.rss_warm:.1f} -> {soak.rss_end:.1f} MB)",
            f"< {MAX_GROWTH_MB:g} MB",
            f"max {rss_max:.1f} MB; warm-up {soak.warmup_s / 60:g} min; the event list "
            f"holds ~{_event_bytes(events):.1f} MB ({len(events)} events)",
            "-",
            bool(growth < MAX_GROWTH_MB),
        ),
    ]
    return rows
