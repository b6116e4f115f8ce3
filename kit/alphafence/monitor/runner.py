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

from alphafence.monitor.commands import Commands
from alphafence.monitor.engine import Engine
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import alert_text, new_event
from alphafence.monitor.feeds import (
    TELEMETRY,
    Feed,
    adsb,
    latest_sample,
    other_systems,
    set_rates,
    telemetry_feeds,
)
from alphafence.monitor.observe import Observer, Step
from alphafence.monitor.options import REROUTE
from alphafence.monitor.reroute_flight import RerouteFlight

TICK_EPSILON_S = 0.005  # the tick wakes this long after its due time (timers may fire early)
CLOCK_S = 1.0  # fences' time windows and ended telemetry streams are looked at this often
ROLLING_FINISH_S = 20.0  # a fence transfer under way at shutdown may take this long to end


class Monitor:
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

    def _feeds(self) -> dict:
        def keep(key):
            if key == "position":

                def deliver(t, value):
                    self.latest[key] = (t, value)
                    self._position_came()

            elif key == "velocity":

                def deliver(t, value):
                    self.latest[key] = (t, value)

            else:  # the mode, the armed state, the GPS fix: a change needs a full check

                def deliver(t, value):
                    old = self.latest[key]
                    self.latest[key] = (t, value)
                    if old is None or old[1] != value:
                        self.engine.invalidate()

            return deliver

        def traffic(t, report):
            self.engine.aircraft(t=t, **report)

        vehicle = self.vehicle
        feeds = telemetry_feeds(vehicle, keep)
        position = feeds["telemetry:position"]
        if position.split:  # the velocity came with the position: check at once
            self._inline_check = True
            position.then = self._check
        feeds["adsb"] = Feed(lambda: adsb(vehicle), traffic, "adsb_unavailable")
        if self.engine.options.mavlink_traffic:
            # every GLOBAL_POSITION_INT on the link crosses into Python: opt-in, for links
            # that carry other aircraft
            feeds["traffic"] = Feed(
                lambda: other_systems(vehicle), traffic, "traffic_link_unavailable"
            )
        if self.engine.options.reroute:
            feeds.update({f"reroute:{k}": f for k, f in self.reroute.feeds().items()})
        return feeds

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
        self._loop = asyncio.get_running_loop()
        try:
            while not stop.is_set():
                due = min(self.engine.tick_due(), self._clock_t + CLOCK_S)
                await asyncio.wait(
                    {stopping},
                    timeout=min(CLOCK_S, max(0.0, due - time.monotonic())) + TICK_EPSILON_S,
                )
                if self._failure is not None:
                    raise self._failure
                events = self.engine.tick(time.monotonic())
                if time.monotonic() - self._clock_t > CLOCK_S:  # ED-269 time windows
                    self._clock_t = time.monotonic()
                    now = datetime.now(timezone.utc)
                    self.engine.fences.set_time(now, self.clock_slack_s)
                    if self.live is not None:
                        self.live.tick(now)
                    events += self._ended_tasks()
                for e in events:
                    self.handle(e)
        finally:
            self._loop = None  # no check after this
            stopping.cancel()
            for t in self.tasks + list(self.pending):
                t.cancel()
            for t in self.tasks + list(self.pending):
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await t
            if self.rolling is not None:
                await self.rolling.finish(ROLLING_FINISH_S)

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
            if not self.observers and self.rolling is None and self._skip():
                return  # the last full check proves this position: nothing to do
            sample = latest_sample(self.latest)
            if sample is None:
                return
            events = self._step(sample)
            if self.rolling is not None:  # a re-upload, when due, as a task
                self.rolling.consider(sample)
            for e in events:
                self.handle(e)
        except Exception as exc:  # noqa: BLE001 - handed to run(), which raises it
            self._failure = exc

    def _skip(self) -> bool:
        """Whether the engine takes the latest position without a check (its values read as
        they are, no Sample built: :meth:`Engine.skip <alphafence.monitor.engine.Engine.skip>`)."""
        pos, vel = self.latest["position"], self.latest["velocity"]
        if pos is None or vel is None:
            return False
        p, v = pos[1], vel[1]
        lat, lon, alt = p.latitude_deg, p.longitude_deg, p.relative_altitude_m
        return self.engine.skip(pos[0], lat, lon, alt, v.north_m_s, v.east_m_s)

    async def _follow(self, name, feed):
        """Deliver every value of ``feed`` (then tell the observers); a feed that fails is its
        ``unavailable`` event, or ends the task (telemetry: see :meth:`_ended_tasks`)."""
        stream = name.split(":", 1)[-1]

        def take(value):
            t = time.monotonic()
            feed.deliver(t, value)
            if self.observers:
                parts = zip(feed.split, value) if feed.split else ((stream, value),)
                for part, v in list(parts):
                    for observer in self.observers:
                        observer.on_value(part, t, v)
            if feed.then is not None:
                feed.then()

        def pushed(value):  # called by the link as it parses: a failure goes to run()
            try:
                take(value)
            except Exception as exc:  # noqa: BLE001 - run() raises it
                self._failure = self._failure or exc

        try:
            if feed.listen is not None:
                with feed.listen(pushed):
                    await asyncio.Event().wait()  # until cancelled
            async for value in feed.open():
                take(value)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            if feed.unavailable is None:
                raise
            self.log.put(new_event(feed.unavailable, error=str(exc)))

    def _step(self, sample):
        started, checks = time.monotonic(), self.engine.checks
        events = self.engine.step(sample)
        if self.observers:
            step = Step(
                sample, started, self.engine.checks > checks, self.engine.sm.level, tuple(events)
            )
            for observer in self.observers:
                observer.on_step(step)
        return events

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
                error = "" if exc is None else f"{type(exc).__name__}: {exc}"
                events.append(new_event("telemetry_task_ended", task=task.get_name(), error=error))
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
                self._spawn(self.commands.act(event["action"]))

    def _spawn(self, coro):
        task = asyncio.create_task(coro)
        self.pending.add(task)
        task.add_done_callback(self.pending.discard)
        return task
