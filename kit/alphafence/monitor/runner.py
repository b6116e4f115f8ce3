"""The async companion monitor: MAVSDK telemetry in, the engine's decisions out.

Telemetry subscriptions only update the latest state; a checker wakes on every new position
and at least every 0.1 s; alerts (STATUSTEXT to the ground station) and actions (brake, RTL,
land) run as their own tasks; the event log is written by its own task off the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections import deque
from datetime import datetime, timezone

from alphafence.monitor.engine import Engine, Sample, alert_text

TICK_S = 0.1


class EventLog:
    """JSON lines, appended by a background task (file I/O never blocks the loop).

    ``events`` keeps the latest ``keep`` events in memory (for tests and the summary). A write
    that fails (disk full, the directory gone) is reported once through ``echo`` and as a
    ``log_write_failed`` event, the lines it held are counted as lost, and the writer keeps
    trying with the next ones: the monitor itself never stops or hangs for its log."""

    def __init__(self, path=None, echo=None, keep: int = 10_000):
        self.path = path
        self.echo = echo
        self.queue: asyncio.Queue = asyncio.Queue()
        self.task = asyncio.create_task(self._write()) if path else None
        self.events: deque = deque(maxlen=keep)
        self.lost = 0  # lines that could not be written
        self.write_error: str | None = None

    def put(self, event):
        self.events.append(event)
        if self.echo:
            self.echo(event)
        if self.task and not self.task.done():
            self.queue.put_nowait(json.dumps(event, separators=(",", ":")))

    async def _write(self):
        while True:
            lines = [await self.queue.get()]
            while not self.queue.empty():
                lines.append(self.queue.get_nowait())
            try:
                await asyncio.to_thread(_append, self.path, lines)
            except OSError as exc:
                self.lost += len(lines)
                if self.write_error is None:
                    self.write_error = f"{self.path}: {exc.strerror or exc}"
                    self.put(
                        {
                            "time": round(time.monotonic(), 3),
                            "event": "log_write_failed",
                            "error": self.write_error,
                        }
                    )
            else:
                self.write_error = None

    async def close(self, timeout: float = 5.0):
        if self.task:
            deadline = time.monotonic() + timeout
            while not self.queue.empty() and not self.task.done():
                if time.monotonic() > deadline:
                    self.lost += self.queue.qsize()
                    break
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.05)
            self.task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self.task


def check_log_path(path) -> None:
    """Refuse an event log that cannot be appended to, before any link is opened."""
    from alphafence.errors import InputError

    try:
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        raise InputError(path, f"cannot write the event log: {exc.strerror}") from None


def _num(fields, key, default=None) -> float:
    """A finite number from a message's fields (ValueError when missing or not finite)."""
    value = fields.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(key)
    value = float(value)  # OverflowError for an absurd integer
    if not math.isfinite(value):
        raise ValueError(key)
    return value


def parse_adsb(fields_json):
    """An ADSB_VEHICLE message's fields (MAVSDK mavlink_direct JSON) -> Engine.aircraft kwargs,
    or None when it carries no usable position (missing, out of range, not finite)."""
    try:
        f = json.loads(fields_json)
        lat, lon = _num(f, "lat") / 1e7, _num(f, "lon") / 1e7
        alt = _num(f, "altitude") / 1000.0
        speed = _num(f, "hor_velocity", 0) / 100.0
        heading = math.radians(_num(f, "heading", 0) / 100.0)
        climb = _num(f, "ver_velocity", 0) / 100.0
        callsign = str(f.get("callsign", "")).strip("\x00 ")[:16]
        key = f.get("ICAO_address")
        if key is None or isinstance(key, dict | list | float):
            return None
    except (ValueError, KeyError, TypeError, OverflowError, AttributeError):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return {
        "key": key,
        "lat": lat,
        "lon": lon,
        "alt_amsl_m": alt,
        "ve": speed * math.sin(heading),
        "vn": speed * math.cos(heading),
        "vu": climb,
        "callsign": callsign,
    }


def parse_global_position(system_id, fields_json):
    """Another MAVLink system's GLOBAL_POSITION_INT -> Engine.aircraft kwargs, or None."""
    try:
        f = json.loads(fields_json)
        lat, lon = _num(f, "lat") / 1e7, _num(f, "lon") / 1e7
        out = {
            "key": f"mavlink/{int(system_id)}",
            "lat": lat,
            "lon": lon,
            "alt_amsl_m": _num(f, "alt") / 1000.0,
            "ve": _num(f, "vy", 0) / 100.0,
            "vn": _num(f, "vx", 0) / 100.0,
            "vu": -_num(f, "vz", 0) / 100.0,
            "callsign": f"MAV{int(system_id)}",
        }
    except (ValueError, KeyError, TypeError, OverflowError, AttributeError):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return out


def _append(path, lines):
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


class Monitor:
    """Commands to the vehicle go out one at a time (``_command``), each finishing even when
    the task that sent it is cancelled: a brake or RTL is never overtaken by a re-route's goto.
    """

    # re-routing (--imminent-action reroute)
    TARGET_HZ = 2.0  # the GUIDED target (POSITION_TARGET_GLOBAL_INT), asked for only then
    TARGET_FRESH_S = 3.0  # an older GUIDED target is not the vehicle's current one
    REROUTER_WAIT_S = 2.0  # a re-route asked for while the planner is still being built
    MISSION_TIMEOUT_S = 5.0
    MISSION_RETRY_S = 10.0  # a failed mission download is retried this often (and on demand)
    ARRIVE_M = 2.0  # a re-route waypoint is reached within this
    ARRIVE_POLL_S = 0.05

    def __init__(self, vehicle, fences, options, log: EventLog, rate_hz: float = 10.0, record=None):
        self.vehicle = vehicle
        self.record = record  # a list that receives every telemetry sample (for replay tests)
        self.engine = Engine(fences, options)
        self.log = log
        self.rate_hz = rate_hz
        self.latest = {"position": None, "velocity": None, "mode": None, "armed": None, "gps": None}
        self.new_position = asyncio.Event()
        self.tasks = []
        self.pending = set()
        self._clock_t = -math.inf
        self._ended = set()  # tasks whose end has been reported
        self._command_lock = asyncio.Lock()
        # re-routing (options.imminent_action "reroute" with enforce)
        self.rerouter = None
        self.rerouter_task = None
        self.reroute_task = None
        self.target = None  # (time, lon, lat): the GUIDED target the vehicle reports
        self.progress = None  # (current, total): the AUTO mission's progress
        self.mission = None  # (total, items): the mission as last downloaded
        self._mission_fetch = None
        self._mission_tried = -math.inf

    async def run(self, stop: asyncio.Event):
        tel = self.vehicle.telemetry
        for setter in (tel.set_rate_position, tel.set_rate_velocity_ned):
            with contextlib.suppress(Exception):
                await setter(self.rate_hz)
        streams = {
            "position": tel.subscribe_position,
            "velocity": tel.subscribe_velocity_ned,
            "mode": tel.subscribe_flight_mode,
            "armed": tel.subscribe_armed,
            "gps": tel.subscribe_gps_info,
        }
        self.tasks = [
            asyncio.create_task(
                self._follow(subscribe(), key, wake=key == "position"), name=f"telemetry:{key}"
            )
            for key, subscribe in streams.items()
        ]
        self.tasks.append(asyncio.create_task(self._adsb()))
        if self.engine.options.mavlink_traffic:
            # every GLOBAL_POSITION_INT on the link, the vehicle's own at the telemetry rate
            # included, crosses into Python: opt-in, for links that carry other aircraft
            self.tasks.append(asyncio.create_task(self._other_systems()))
        if self.engine.options.reroute:
            self.rerouter_task = asyncio.create_task(self._build_rerouter())
            self.tasks += [
                self.rerouter_task,
                asyncio.create_task(self._targets()),
                asyncio.create_task(self._mission_progress()),
            ]
        try:
            while not stop.is_set():
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self.new_position.wait(), TICK_S)
                events = []
                if self.new_position.is_set():
                    self.new_position.clear()
                    sample = self._sample()
                    if sample is not None:
                        if self.record is not None:
                            self.record.append(sample)
                        events += self.engine.step(sample)
                events += self.engine.tick(time.monotonic())
                if time.monotonic() - self._clock_t > 1.0:  # ED-269 time windows
                    self._clock_t = time.monotonic()
                    self.engine.fences.set_time(datetime.now(timezone.utc))
                    events += self._ended_tasks()
                for e in events:
                    self._handle(e)
        finally:
            for t in self.tasks + list(self.pending):
                t.cancel()
            for t in self.tasks + list(self.pending):
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await t

    def _ended_tasks(self):
        """A telemetry stream that ended (MAVSDK raised, or the stream closed) is an event,
        once: its value would otherwise go stale without a word."""
        events = []
        for task in self.tasks:
            if not task.get_name().startswith("telemetry:"):
                continue
            if task.done() and task not in self._ended and not task.cancelled():
                self._ended.add(task)
                exc = task.exception()
                events.append(
                    {
                        "time": round(time.monotonic(), 3),
                        "event": "telemetry_task_ended",
                        "task": task.get_name(),
                        "error": "" if exc is None else f"{type(exc).__name__}: {exc}",
                    }
                )
        return events

    async def _follow(self, stream, key, wake=False):
        async for value in stream:
            self.latest[key] = (time.monotonic(), value)
            if wake:
                self.new_position.set()

    async def _adsb(self):
        """ADSB_VEHICLE reports (forwarded by ArduPilot from its ADS-B receiver) -> traffic."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        try:
            stream = MavlinkDirectAsync(self.vehicle.system).subscribe_message("ADSB_VEHICLE")
            async for message in stream:
                report = parse_adsb(message.fields_json)
                if report is not None:
                    self.engine.aircraft(t=time.monotonic(), **report)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # no ADS-B is an event, never a crash
            self.log.put(
                {"time": round(time.monotonic(), 3), "event": "adsb_unavailable", "error": str(exc)}
            )

    async def _other_systems(self):
        """Other MAVLink systems on the link (other drones, a chase aircraft) -> traffic."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        try:
            own = int(await self.vehicle.system.get_system_id())
        except Exception:
            own = 1  # ArduPilot's default SYSID_THISMAV
        try:
            stream = MavlinkDirectAsync(self.vehicle.system).subscribe_message(
                "GLOBAL_POSITION_INT"
            )
            async for message in stream:
                if message.system_id in (own, 0):
                    continue
                report = parse_global_position(message.system_id, message.fields_json)
                if report is not None:
                    self.engine.aircraft(t=time.monotonic(), **report)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "traffic_link_unavailable",
                    "error": str(exc),
                }
            )

    def _sample(self):
        pos = self.latest["position"]
        if pos is None:
            return None
        t, p = pos
        vel = self.latest["velocity"]
        vn, ve = (vel[1].north_m_s, vel[1].east_m_s) if vel else (0.0, 0.0)
        mode = self.latest["mode"]
        armed = self.latest["armed"]
        return Sample(
            t,
            p.latitude_deg,
            p.longitude_deg,
            p.relative_altitude_m,
            vn,
            ve,
            mode[1].name if mode else None,
            armed[1] if armed else None,
            alt_amsl_m=p.absolute_altitude_m,
            gps_fix=int(self.latest["gps"][1].fix_type) if self.latest["gps"] else None,
            vd=vel[1].down_m_s if vel else 0.0,
        )

    def _handle(self, event):
        self.log.put(event)
        text = alert_text(event)
        if text:
            self._spawn(self._alert(text, event))
        if event["event"] == "reroute_cancelled":
            task = self.reroute_task
            if task is not None and not task.done() and task is not asyncio.current_task():
                task.cancel()
        if event["event"] == "action":
            from alphafence.monitor.engine import REROUTE

            if event["action"] == REROUTE:
                self.reroute_task = self._spawn(self._reroute())
            else:
                self._spawn(self._act(event["action"]))

    def _spawn(self, coro):
        task = asyncio.create_task(coro)
        self.pending.add(task)
        task.add_done_callback(self.pending.discard)
        return task

    async def _command(self, call, *args):
        """``await call(*args)`` (a MAVSDK command) after any command still under way, in a task
        of its own: cancelling the caller does not cut it off halfway (MAVSDK's goto is a mode
        change followed by DO_REPOSITION), and the next command waits for it."""

        async def locked():
            async with self._command_lock:
                return await call(*args)

        task = self._spawn(locked())
        # its outcome is the caller's; retrieved here too in case the caller is gone
        task.add_done_callback(lambda t: t.cancelled() or t.exception())
        return await asyncio.shield(task)

    async def _alert(self, text, event):
        from mavsdk.asyncio.plugins.server_utility import ServerUtilityAsync
        from mavsdk.plugins.server_utility import StatusTextType

        severity = (
            StatusTextType.CRITICAL
            if event.get("level") in ("IMMINENT", "BREACH")
            else StatusTextType.WARNING
        )
        try:
            await ServerUtilityAsync(self.vehicle.system).send_status_text(severity, text)
        except Exception as exc:  # an alert that cannot be sent is logged, never fatal
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "alert_failed",
                    "text": text,
                    "error": str(exc),
                }
            )

    async def _act(self, action):
        act = self.vehicle.action
        try:
            if action == "brake":
                await self._command(act.hold)
            elif action == "rtl":
                await self._command(act.return_to_launch)
            elif action == "land":
                await self._command(act.land)
            self.log.put(
                {"time": round(time.monotonic(), 3), "event": "action_done", "action": action}
            )
        except Exception as exc:
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "action_failed",
                    "action": action,
                    "error": str(exc),
                }
            )

    # -- re-routing -------------------------------------------------------------------
    def _now_event(self, kind, **extra):
        return {"time": round(time.monotonic(), 3), "event": kind, **extra}

    async def _build_rerouter(self):
        """The route planner over every fence, built once, in a worker thread."""
        from alphafence.monitor.reroute import Rerouter

        t0 = time.monotonic()
        try:
            self.rerouter = await Rerouter.build(
                self.engine.fences.records, self.engine.options.reroute_clearance_m
            )
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # no planner: every re-route falls back to the brake
            self.log.put(self._now_event("reroute_unavailable", error=str(exc)))
            return
        self.log.put(
            self._now_event(
                "reroute_ready",
                build_s=round(time.monotonic() - t0, 3),
                clearance_m=self.rerouter.clearance,
            )
        )

    async def _targets(self):
        """The vehicle's GUIDED target (POSITION_TARGET_GLOBAL_INT, which ArduPilot sends only
        when asked and only while it flies to a position in GUIDED)."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        from alphafence.monitor.reroute import (
            MAV_CMD_SET_MESSAGE_INTERVAL,
            POSITION_TARGET_GLOBAL_INT_ID,
            parse_position_target,
        )

        try:
            own = int(await self.vehicle.system.get_system_id())
        except Exception:
            own = 1
        direct = MavlinkDirectAsync(self.vehicle.system)
        fields = {
            "target_system": own,
            "target_component": 1,
            "command": MAV_CMD_SET_MESSAGE_INTERVAL,
            "confirmation": 0,
            "param1": POSITION_TARGET_GLOBAL_INT_ID,
            "param2": 1e6 / self.TARGET_HZ,
            **{f"param{k}": 0 for k in range(3, 8)},
        }
        try:
            stream = direct.subscribe_message("POSITION_TARGET_GLOBAL_INT")
            await direct.send_command(
                MavlinkMessage("COMMAND_LONG", 0, 0, own, 1, json.dumps(fields))
            )
            async for message in stream:
                if message.system_id not in (own, 0):
                    continue
                target = parse_position_target(message.fields_json)
                if target is not None:
                    self.target = (time.monotonic(), *target)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # then GUIDED re-routes aim beyond the fence instead
            self.log.put(self._now_event("reroute_target_unavailable", error=str(exc)))

    async def _mission_progress(self):
        """AUTO's current item; the mission itself is downloaded when it changes."""
        try:
            async for p in self.vehicle.mission_raw.subscribe_mission_progress():
                self.progress = (int(p.current), int(p.total))
                stale = self.mission is None or self.mission[0] != p.total
                due = time.monotonic() - self._mission_tried > self.MISSION_RETRY_S
                if self.progress[1] > 0 and stale and due:
                    self._fetch_mission()
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self.log.put(self._now_event("reroute_mission_unavailable", error=str(exc)))

    def _fetch_mission(self):
        if self._mission_fetch is None or self._mission_fetch.done():
            self._mission_tried = time.monotonic()
            self._mission_fetch = self._spawn(self._download_mission())
        return self._mission_fetch

    async def _download_mission(self):
        total = self.progress[1] if self.progress else None
        try:
            items = await asyncio.wait_for(
                self.vehicle.mission_raw.download_mission(), self.MISSION_TIMEOUT_S
            )
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # then AUTO re-routes aim beyond the fence instead
            self.log.put(self._now_event("reroute_mission_unavailable", error=str(exc)))
            return None
        self.mission = (total if total is not None else len(items), list(items))
        return self.mission[1]

    async def _mission_goal(self):
        """(goal, resume_at) from the AUTO mission, or (None, current item) if it has none."""
        from alphafence.monitor.reroute import mission_goal

        if self.progress is None:
            return None, None
        current, total = self.progress
        if self.mission is None or self.mission[0] != total:
            with contextlib.suppress(Exception):
                await asyncio.shield(self._fetch_mission())
        if self.mission is None:
            return None, current
        goal = mission_goal(self.mission[1], current)
        return (goal, current + 1) if goal is not None else (None, current)

    async def _goal(self, s):
        """(goal (lon, lat), where it came from, mission item to resume at) or Nones."""
        if s.mode == "OFFBOARD" and self.target is not None:  # ArduPilot's GUIDED
            t, lon, lat = self.target
            if time.monotonic() - t <= self.TARGET_FRESH_S:
                return (lon, lat), "guided target", None
        resume_at = None
        if s.mode == "MISSION":  # AUTO
            goal, resume_at = await self._mission_goal()
            if goal is not None:
                return goal, f"mission item {resume_at - 1}", resume_at
        goal = await asyncio.to_thread(self.rerouter.goal_beyond, s.lon, s.lat, s.ve, s.vn)
        if goal is not None:
            return goal, "beyond the fence", resume_at
        return None, None, None

    async def _reroute(self):
        """Plan and fly a re-route; on no route (or any failure) the engine's fallback."""
        from alphafence.monitor.reroute import RerouteFailed

        try:
            await self._fly_reroute()
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            failed = isinstance(exc, RerouteFailed)
            why = str(exc) if failed else f"{type(exc).__name__}: {exc}"
            for e in self.engine.reroute_failed(time.monotonic(), " ".join(why.split())):
                self._handle(e)

    async def _fly_reroute(self):
        from alphafence.monitor.reroute import RerouteFailed, leg_timeout_s, metres, planning_lead_m
        from alphafence.route.roadmap import NoRoute

        s = self.engine.last
        t0 = time.monotonic()
        if self.rerouter is None and self.rerouter_task is not None:
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(self.rerouter_task), self.REROUTER_WAIT_S)
        if self.rerouter is None:
            raise RerouteFailed("no route planner (see reroute_unavailable)")
        if s.alt_amsl_m is None:
            raise RerouteFailed("no altitude (AMSL) to fly the re-route at")
        goal, source, resume_at = await self._goal(s)
        if goal is None:
            raise RerouteFailed(
                "no goal: no target known and no clear point beyond the fence ahead"
            )
        lead = planning_lead_m(math.hypot(s.vn, s.ve), self.engine.options.braking)
        try:
            plan = await asyncio.to_thread(self.rerouter.plan, s.lon, s.lat, s.ve, s.vn, goal, lead)
        except NoRoute as exc:
            raise RerouteFailed(str(exc)) from None
        was_auto = s.mode == "MISSION"
        for e in self.engine.reroute_started(
            time.monotonic(),
            mode_change=s.mode != "OFFBOARD",
            goal=[round(goal[1], 7), round(goal[0], 7)],
            goal_source=source,
            waypoints=[list(w) for w in plan.waypoints],
            length_m=round(plan.length_m, 1),
            clearance_m=round(plan.clearance_m, 2),
            plan_s=round(time.monotonic() - t0, 3),
        ):
            self._handle(e)
        act = self.vehicle.action
        alt = float(s.alt_amsl_m)
        here = (s.lat, s.lon)
        for k, (lat, lon) in enumerate(plan.waypoints):
            await self._command(act.goto_location, lat, lon, alt, float("nan"))
            leg = metres(here, (lat, lon))
            if not await self._arrive(lat, lon, leg_timeout_s(leg)):
                raise RerouteFailed(
                    f"waypoint {k + 1} of {len(plan.waypoints)} not reached within "
                    f"{leg_timeout_s(leg):.0f} s"
                )
            here = (lat, lon)
        resume = was_auto and resume_at is not None and self.progress is not None
        resume = resume and resume_at < self.progress[1]
        for e in self.engine.reroute_done(
            time.monotonic(),
            resume=resume,
            duration_s=round(time.monotonic() - t0, 2),
            resume_at=resume_at if resume else None,
        ):
            self._handle(e)
        if resume:
            try:
                await self._command(self.vehicle.mission_raw.set_current_mission_item, resume_at)
                await self._command(self.vehicle.mission_raw.start_mission)
            except Exception as exc:  # the vehicle holds at the goal in GUIDED
                self.log.put(
                    self._now_event(
                        "action_failed", action="resume_mission", item=resume_at, error=str(exc)
                    )
                )

    async def _arrive(self, lat, lon, timeout):
        from alphafence.monitor.reroute import metres

        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            pos = self.latest["position"]
            if pos is not None:
                p = pos[1]
                if metres((p.latitude_deg, p.longitude_deg), (lat, lon)) <= self.ARRIVE_M:
                    return True
            await asyncio.sleep(self.ARRIVE_POLL_S)
        return False


async def run_monitor(
    url,
    fences,
    options,
    log_path=None,
    stop: asyncio.Event | None = None,
    echo=None,
    timeout: float = 10.0,
    signing_key: bytes | None = None,
):
    from alphafence.vehicle.link import open_vehicle

    stop = stop or asyncio.Event()
    log = EventLog(log_path, echo)
    try:
        async with open_vehicle(url, timeout, signing_key) as vehicle:
            monitor = Monitor(vehicle, fences, options, log)
            await monitor.run(stop)
            return monitor
    finally:
        await log.close()
