"""The async companion monitor: the parts wired together on one vehicle link (either link:
:mod:`alphafence.vehicle.link`).

Each feed (:mod:`alphafence.monitor.feeds`) is followed by a task of its own and only updates
the latest state; a new position is checked at once when its velocity came with it (the
pymavlink link), else it schedules one check (a callback, not a task: at 50 Hz the wake-ups
are most of the cost), which steps the engine (:mod:`alphafence.monitor.engine`) on the
latest values; a loop ticks when telemetry would turn stale and every second (time windows,
ended streams), sleeping in between; every event it decides is logged
(:mod:`alphafence.monitor.eventlog`, written by its own task off the event loop), alerted and
acted on (:mod:`alphafence.monitor.commands`, each alert and action in a task of its own);
re-routes are flown by :mod:`alphafence.monitor.reroute_flight`. Observers
(:mod:`alphafence.monitor.observe`) see every value, step and event.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from datetime import datetime, timezone

from alphafence.geo.coords import E7
from alphafence.monitor.commands import Commands
from alphafence.monitor.engine import Engine
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import alert_text
from alphafence.monitor.feeds import (
    TELEMETRY,
    latest_sample,
    set_rates,
)
from alphafence.monitor.observe import Observer, Step
from alphafence.monitor.options import REROUTE
from alphafence.monitor.reroute_flight import RerouteFlight
from alphafence.monitor.runner_feeds import FeedTasks

TICK_EPSILON_S = 0.005  # the tick wakes this long after its due time (timers may fire early)
CLOCK_S = 1.0  # fences' time windows and ended telemetry streams are looked at this often
# while positions come, the clock's work is done and the loop's wake-up moved on this often
# (within CLOCK_S and the staleness limit, so the wake-up never comes while they do)
REARM_S = 0.8
ROLLING_FINISH_S = 20.0  # a fence transfer under way at shutdown may take this long to end


class Monitor(FeedTasks):
    """The monitor on one vehicle: feeds in, the engine's decisions out.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle link (:class:`~alphafence.vehicle.base.Vehicle`).
    fences : FenceSet
        Every fence.
    options : MonitorOptions
        What to predict, decide and command.
    log : EventLog
        Where every event goes.
    rate_hz : float
        The position and velocity rate asked of the vehicle.
    observers : iterable of Observer
        Told of every value, step and event (see :meth:`add_observer`).

    Attributes
    ----------
    engine : Engine
        The decisions (``engine.checks``: positions checked so far).
    latest : dict
        ``{stream: (arrival time, MAVSDK value) or None}`` for the telemetry streams.
    feeds : dict
        ``{name: Feed}``: the streams :meth:`run` follows, each in a task named after it
        (telemetry streams as ``telemetry:<stream>``); a stub vehicle's test may leave some out.
    tasks : list of asyncio.Task
        The feeds' tasks (and the planner's) while :meth:`run` runs.
    commands : Commands
        Actions and alerts to the vehicle.
    reroute : RerouteFlight
        Re-routes (``--imminent-action reroute``).
    rolling : RollingFence or None
        The rolling onboard fence (``--onboard rolling``): each new position may start a
        re-upload (:mod:`alphafence.monitor.rolling`).
    """

    def __init__(
        self, vehicle, fences, options, log: EventLog, rate_hz=10.0, observers=(), live=None
    ):
        self.vehicle = vehicle
        self.engine = Engine(fences, options)
        self.log = log
        self.rate_hz = rate_hz
        self.latest = dict.fromkeys(TELEMETRY)
        self._loop = None  # while run() runs: positions are checked
        self._check_due = False  # a check is scheduled
        self._inline_check = False  # positions are checked as their feed delivers them
        self._failure = None  # what a check raised, for run() to raise
        self.observers: list[Observer] = []
        self.tasks = []
        self.pending = set()  # alerts, actions, commands, re-routes under way
        self._clock_t = -math.inf
        self._wake = asyncio.Event()  # the loop's: stale telemetry, the clock, a failure, stop
        self._timer = None  # what sets it when due
        self._armed_t = -math.inf
        self._ended = set()  # tasks whose end has been reported
        self.commands = Commands(vehicle, log, self._spawn)
        self.reroute = RerouteFlight(
            vehicle, self.engine, self.commands, log, self.latest, self.handle, self._spawn
        )
        self.rolling = None  # --onboard rolling: alphafence.monitor.rolling.RollingFence
        if options.onboard == "rolling":
            from alphafence.monitor.rolling import RollingFence

            self.rolling = RollingFence(
                vehicle, fences, options.rolling, options.braking, self.handle, self.reload_onboard
            )
        self.clock_slack_s = 0.0  # how far this clock may be off (a live source's Date says)
        self.live = None  # --source: alphafence.monitor.live.LiveSource
        if live is not None:
            from alphafence.monitor.live import LiveSource
            from alphafence.monitor.live_zones import split_copy

            self.live = LiveSource(self, live, *split_copy(fences.records))
        self.feeds = self._feeds()
        for observer in observers:
            self.add_observer(observer)

    def add_observer(self, observer: Observer) -> None:
        """Tell ``observer`` of every feed value, engine step and logged event from now on.

        Parameters
        ----------
        observer : Observer
            Its ``on_value``, ``on_step`` and ``on_event`` are called on the event loop, in
            the order things happen (see :mod:`alphafence.monitor.observe`).
        """
        self.observers.append(observer)
        if hasattr(observer, "on_engine"):
            observer.on_engine(self.engine)
        self.log.add_listener(observer.on_event)

    async def run(self, stop: asyncio.Event) -> None:
        """Follow the feeds and check every new position until ``stop`` is set; then cancel
        every task the monitor started.

        Parameters
        ----------
        stop : asyncio.Event
            Set it to end the monitor.
        """
        if hasattr(self.engine.fences, "index"):
            self.engine.fences.index()  # before the first position, not at it
        # asked for beside the feeds: a vehicle that does not answer must not delay the checks
        self.tasks = [
            asyncio.create_task(set_rates(self.vehicle.telemetry, self.rate_hz), name="rates")
        ]
        if self.engine.options.reroute:
            self.reroute.planner_task = asyncio.create_task(
                self.reroute.build_planner(), name="reroute:planner"
            )
            self.tasks.append(self.reroute.planner_task)
        self.tasks += [
            asyncio.create_task(self._follow(name, feed), name=name)
            for name, feed in self.feeds.items()
        ]
        if self.live is not None:
            self.tasks.append(asyncio.create_task(self.live.run(stop), name="source"))
        if self.engine.options.watch_onboard:  # the checks start on the fences meanwhile
            start = asyncio.create_task(self.reload_onboard("start"), name="onboard:start")
            self.tasks.append(start)
            if self.rolling is not None:  # one fence transfer at a time
                self.rolling.after = start
        stopping = asyncio.ensure_future(stop.wait())
        stopping.add_done_callback(lambda _: self._wake.set())
        self._loop = asyncio.get_running_loop()
        try:
            while not stop.is_set():
                self._arm()
                await self._wake.wait()
                self._wake.clear()
                if self._failure is not None:
                    raise self._failure
                now = time.monotonic()
                events = self.engine.tick(now)
                if now - self._clock_t > CLOCK_S:
                    events += self._clock(now)
                for e in events:
                    self.handle(e)
        finally:
            if self._timer is not None:
                self._timer.cancel()
            self._loop = None  # no check after this
            stopping.cancel()
            for t in self.tasks + list(self.pending):
                t.cancel()
            for t in self.tasks + list(self.pending):
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await t
            if self.rolling is not None:
                await self.rolling.finish(ROLLING_FINISH_S)

    def _arm(self) -> None:
        """Wake the loop when telemetry would turn stale or the clock is due, whichever comes
        first. While positions come, each does the clock's work when due (:meth:`_check`) and
        moves this wake-up on, at most every :data:`REARM_S`: the loop then never wakes."""
        due = min(self.engine.tick_due(), self._clock_t + CLOCK_S) + TICK_EPSILON_S
        if self._timer is not None:
            self._timer.cancel()
        self._armed_t = now = time.monotonic()
        self._timer = self._loop.call_at(min(due, now + CLOCK_S), self._wake.set)

    def _loop_work(self, now) -> None:
        """What the loop would wake for, done by a position instead, every :data:`REARM_S`:
        the clock's work, and the loop's wake-up moved on."""
        if now - self._armed_t > REARM_S:
            for e in self._clock(now):
                self.handle(e)
            self._arm()

    def _clock(self, now) -> list:
        """Each second: fences' time windows, a live source's windows, ended streams."""
        self._clock_t = now
        utc = datetime.now(timezone.utc)
        self.engine.fences.set_time(utc, self.clock_slack_s)
        if self.live is not None:
            self.live.tick(utc)
        return self._ended_tasks()

    def _position_came(self) -> None:
        """A new position: check it as soon as the values that came with it are in (one
        callback however many positions arrive before it runs: the latest is checked)."""
        if self._loop is not None and not self._check_due and not self._inline_check:
            self._check_due = True
            self._loop.call_soon(self._check)

    def _check(self) -> None:
        """Step the engine on the latest sample, consider a rolling re-upload, act on the
        events. A failure stops the monitor (``run`` raises it), as it did inline."""
        self._check_due = False
        if self._loop is None or self._failure is not None:
            return
        try:
            self._loop_work(time.monotonic())
            if not self.observers and self.rolling is None and self._skip():
                return  # the last full check proves this position: nothing to do
            sample = latest_sample(self.latest, getattr(self.vehicle, "autopilot", "ardupilot"))
            if sample is None:
                return
            events = self._step(sample)
            if self.rolling is not None:  # a re-upload, when due, as a task
                self.rolling.consider(sample)
            for e in events:
                self.handle(e)
        except Exception as exc:  # noqa: BLE001 - handed to run(), which raises it
            self._failure = exc
            self._wake.set()

    def _skip(self) -> bool:
        """Whether the engine takes the latest position without a check (its values read as
        they are, no Sample built: :meth:`Engine.skip <alphafence.monitor.engine.Engine.skip>`)."""
        pos, vel = self.latest["position"], self.latest["velocity"]
        if pos is None or vel is None:
            return False
        p, v = pos[1], vel[1]
        lat, lon, alt = p.latitude_deg, p.longitude_deg, p.relative_altitude_m
        return self.engine.skip(pos[0], lat, lon, alt, v.north_m_s, v.east_m_s)

    def _step(self, sample):
        started, checks = time.monotonic(), self.engine.checks
        events = self.engine.step(sample)
        if self.observers:
            known = self.live is None or self.live.known
            step = Step(sample, started, self.engine.checks > checks, self.engine.sm.level,
                        tuple(events), known)  # fmt: skip
            for observer in self.observers:
                observer.on_step(step)
        return events

    def set_fences(self, fences) -> None:
        """Check against ``fences`` (a :class:`~alphafence.awareness.fenceset.FenceSet`, in
        the same frame) from the next position on: a live source's zones changed. The rolling
        onboard fence is compiled again, the re-route planner rebuilt."""
        fences.set_time(datetime.now(timezone.utc), self.clock_slack_s)
        self.engine.set_fences(fences)
        if self.rolling is not None:
            self.rolling.set_fences(fences)
        if self.engine.options.reroute and self._loop is not None:
            self.reroute.planner_task = self._spawn(self.reroute.build_planner())

    def _skip_raw(self, lat, lon, alt, vn, ve) -> bool:
        """Whether a position, as the wire has it (1e-7 degrees, mm above home, cm/s), needs
        nothing done: the engine's lazy check takes it (:meth:`Engine.skip
        <alphafence.monitor.engine.Engine.skip>`) and no loop work is due. Then no value is
        built for it: ``latest`` keeps the last position delivered, ``engine.last`` has this
        one. With an observer or a rolling fence every position is delivered."""
        if self.observers or self.rolling is not None or self._loop is None:
            return False
        now = time.monotonic()
        if not self.engine.skip(now, lat / E7, lon / E7, alt / 1000.0, vn / 100.0, ve / 100.0):
            return False
        if now - self._armed_t > REARM_S:
            self._loop_work(now)
        return True

    async def reload_onboard(self, cause: str = "upload") -> list:
        """Download the vehicle's fence and check against it from now on, as a layer of its
        own beside the full-resolution fences (the runner does it at start; call it after
        every upload the monitor makes).

        Parameters
        ----------
        cause : str
            Why (``"start"``, ``"upload"``, ...): the events' ``cause``.

        Returns
        -------
        list of dict
            The events, already handled: ``onboard_fence`` (``items``, ``fences``,
            ``seconds``), ``onboard_none`` (the vehicle holds no fence) or ``onboard_failed``
            (the download failed or brought no valid fence: the layer in use is kept). Never
            raises but for cancellation.
        """
        from alphafence.monitor.onboard import download_layer

        return await download_layer(self, cause)

    def handle(self, event: dict) -> None:
        """Carry out one event: log it (the observers see it), alert the ground station if it
        says something to it, and act (an ``action`` is commanded, a ``reroute`` flown, a
        ``reroute_cancelled`` stops the re-route under way)."""
        self.log.put(event)
        text = alert_text(event)
        if text:
            self._spawn(self.commands.alert(text, event))
        if event["event"] == "reroute_cancelled":
            self.reroute.cancel()
        if event["event"] == "action":
            if event["action"] == REROUTE:
                self.reroute.start()
            else:
                last = self.engine.last
                at = (last.lat, last.lon, last.alt_amsl_m) if last is not None else None
                self._spawn(self.commands.act(event["action"], at))

    def _spawn(self, coro):
        task = asyncio.create_task(coro)
        self.pending.add(task)
        task.add_done_callback(self.pending.discard)
        return task
