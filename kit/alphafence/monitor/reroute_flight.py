"""Flying a re-route (``--imminent-action reroute``): the planner, the vehicle's own goal and
the legs, for the runner.

:class:`RerouteFlight` builds the route planner once (in a worker thread, when the monitor
starts), follows what the vehicle is flying to (its GUIDED target, its AUTO mission; on PX4
the target of its reposition, in Hold, and its Mission) and, when the engine asks for a
re-route, plans one (:mod:`alphafence.monitor.reroute`) and flies it leg by leg with gotos,
then hands control back (the mission resumes at the next item). Whatever goes
wrong (no planner, no goal, no route, a leg not flown in time) ends in the engine's fallback,
the brake, through ``reroute_failed``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time

from alphafence.geo.frame import short_distance_m
from alphafence.mavlink.autopilots import ARDUPILOT
from alphafence.monitor.events import new_event
from alphafence.monitor.feeds import Feed, download_mission, guided_targets, mission_progress
from alphafence.vehicle.values import GOTO_MODE, MISSION_MODE

TARGET_NAMES = {"GUIDED": "guided target", "HOLD": "reposition target"}  # by the goto mode


class RerouteFlight:
    """Re-routes, planned and flown for one monitor.

    Parameters
    ----------
    vehicle : Vehicle
        The MAVSDK connection.
    engine : Engine
        Told when a re-route starts, ends or fails (its events go to ``handle``).
    commands : Commands
        The gotos and the mission's resumption go through it, one command at a time.
    log : EventLog
        Where the planner's and the feeds' own events go.
    latest : dict
        The monitor's latest telemetry (``latest["position"]``: arrival at a waypoint).
    handle : callable
        ``handle(event)``: the monitor carries out an engine event (logs, alerts, acts).
    spawn : callable
        ``spawn(coroutine)`` -> a task the monitor cancels when it stops.

    Attributes
    ----------
    rerouter : Rerouter or None
        The route planner, once built.
    task : asyncio.Task or None
        The re-route being flown (or the last one).
    target : tuple or None
        ``(arrival time, lon, lat)``: the GUIDED target the vehicle last reported.
    progress, mission : tuple or None
        ``(current, total)`` of the AUTO mission; ``(total, items)`` as last downloaded.
    """

    TARGET_HZ = 2.0  # the GUIDED target (POSITION_TARGET_GLOBAL_INT), asked for only then
    TARGET_FRESH_S = 3.0  # an older GUIDED target is not the vehicle's current one
    REROUTER_WAIT_S = 2.0  # a re-route asked for while the planner is still being built
    MISSION_TIMEOUT_S = 5.0
    MISSION_RETRY_S = 10.0  # a failed mission download is retried this often (and on demand)
    ARRIVE_M = 2.0  # a re-route waypoint is reached within this
    ARRIVE_POLL_S = 0.05

    def __init__(self, vehicle, engine, commands, log, latest, handle, spawn):
        self.vehicle = vehicle
        self.engine = engine
        self.commands = commands
        self.log = log
        self.latest = latest
        self.handle = handle
        self.spawn = spawn
        self.rerouter = None
        self.planner_task = None
        self.task = None
        self.target = None
        self.progress = None
        self.mission = None
        self._mission_fetch = None
        self._mission_tried = -math.inf

    @property
    def modes(self) -> tuple:
        """The vehicle's goto mode and mission mode, by its names (ArduPilot's ``GUIDED`` and
        ``AUTO``; on PX4 ``HOLD``, where a reposition flies, and ``MISSION``)."""
        autopilot = getattr(self.vehicle, "autopilot", ARDUPILOT)
        return GOTO_MODE[autopilot], MISSION_MODE[autopilot]

    def feeds(self) -> dict:
        """The streams a re-route needs: ``{"target": Feed, "mission_progress": Feed}``."""
        vehicle = self.vehicle
        return {
            "target": Feed(
                lambda: guided_targets(vehicle, self.TARGET_HZ),
                self.on_target,
                "reroute_target_unavailable",
            ),
            "mission_progress": Feed(
                lambda: mission_progress(vehicle.mission_raw),
                self.on_progress,
                "reroute_mission_unavailable",
            ),
        }

    def on_target(self, t: float, target) -> None:
        """The vehicle's GUIDED target ``(lon, lat)``, arrived at ``t``."""
        self.target = (t, *target)

    def on_progress(self, t: float, progress) -> None:
        """AUTO's ``(current, total)``; the mission is downloaded again when its size changed
        (at most every ``MISSION_RETRY_S``)."""
        self.progress = progress
        stale = self.mission is None or self.mission[0] != progress[1]
        due = time.monotonic() - self._mission_tried > self.MISSION_RETRY_S
        if progress[1] > 0 and stale and due:
            self._fetch_mission()

    async def build_planner(self) -> None:
        """The route planner over the fences, made once, in a worker thread (each re-route
        then routes over the fences near the vehicle and its goal only): ``reroute_ready``,
        or ``reroute_unavailable`` (every re-route then brakes)."""
        from alphafence.monitor.reroute import Rerouter

        t0 = time.monotonic()
        try:
            self.rerouter = await Rerouter.build(
                self.engine.fences.records, self.engine.options.reroute_clearance_m
            )
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # no planner: every re-route falls back to the brake
            self.log.put(new_event("reroute_unavailable", error=str(exc)))
            return
        self.log.put(
            new_event(
                "reroute_ready",
                build_s=round(time.monotonic() - t0, 3),
                clearance_m=self.rerouter.clearance,
            )
        )

    def start(self) -> asyncio.Task:
        """Plan and fly a re-route in a task of its own (``task``)."""
        self.task = self.spawn(self.fly())
        return self.task

    def cancel(self) -> None:
        """Stop the re-route under way (the engine cancelled it), unless called from it."""
        task = self.task
        if task is not None and not task.done() and task is not asyncio.current_task():
            task.cancel()

    async def fly(self) -> None:
        """Plan and fly a re-route; on no route (or any failure) the engine's fallback."""
        from alphafence.monitor.reroute import RerouteFailed

        try:
            await self._fly()
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            failed = isinstance(exc, RerouteFailed)
            why = str(exc) if failed else f"{type(exc).__name__}: {exc}"
            for e in self.engine.reroute_failed(time.monotonic(), " ".join(why.split())):
                self.handle(e)

    async def _fly(self):
        from alphafence.monitor.reroute import RerouteFailed, leg_timeout_s, planning_lead_m
        from alphafence.route.roadmap import NoRoute

        s = self.engine.last
        t0 = time.monotonic()
        if self.rerouter is None and self.planner_task is not None:
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(self.planner_task), self.REROUTER_WAIT_S)
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
        was_auto = s.mode == self.modes[1]
        for e in self.engine.reroute_started(
            time.monotonic(),
            mode_change=s.mode != self.modes[0],
            goal=[round(goal[1], 7), round(goal[0], 7)],
            goal_source=source,
            waypoints=[list(w) for w in plan.waypoints],
            length_m=round(plan.length_m, 1),
            clearance_m=round(plan.clearance_m, 2),
            plan_s=round(time.monotonic() - t0, 3),
        ):
            self.handle(e)
        alt = float(s.alt_amsl_m)
        here = (s.lat, s.lon)
        for k, (lat, lon) in enumerate(plan.waypoints):
            await self.commands.goto(lat, lon, alt)
            leg = short_distance_m(here, (lat, lon))
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
            self.handle(e)
        if resume:
            await self.commands.resume_mission(resume_at)

    async def _goal(self, s):
        """(goal (lon, lat), where it came from, mission item to resume at) or Nones."""
        goto_mode, mission_mode = self.modes
        if s.mode == goto_mode and self.target is not None:
            t, lon, lat = self.target
            if time.monotonic() - t <= self.TARGET_FRESH_S:
                return (lon, lat), TARGET_NAMES[goto_mode], None
        resume_at = None
        if s.mode == mission_mode:
            goal, resume_at = await self._mission_goal()
            if goal is not None:
                return goal, f"mission item {resume_at - 1}", resume_at
        goal = await asyncio.to_thread(self.rerouter.goal_beyond, s.lon, s.lat, s.ve, s.vn)
        if goal is not None:
            return goal, "beyond the fence", resume_at
        return None, None, None

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

    def _fetch_mission(self):
        if self._mission_fetch is None or self._mission_fetch.done():
            self._mission_tried = time.monotonic()
            self._mission_fetch = self.spawn(self._download_mission())
        return self._mission_fetch

    async def _download_mission(self):
        total = self.progress[1] if self.progress else None
        try:
            items = await download_mission(self.vehicle.mission_raw, self.MISSION_TIMEOUT_S)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # then AUTO re-routes aim beyond the fence instead
            self.log.put(new_event("reroute_mission_unavailable", error=str(exc)))
            return None
        self.mission = (total if total is not None else len(items), items)
        return self.mission[1]

    async def _arrive(self, lat, lon, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            pos = self.latest["position"]
            if pos is not None:
                p = pos[1]
                if short_distance_m((p.latitude_deg, p.longitude_deg), (lat, lon)) <= self.ARRIVE_M:
                    return True
            await asyncio.sleep(self.ARRIVE_POLL_S)
        return False
