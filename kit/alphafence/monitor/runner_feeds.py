"""The runner's feeds: which streams the monitor follows, and the task that follows each (a
mixin of :class:`~alphafence.monitor.runner.Monitor`)."""

from __future__ import annotations

import asyncio
import time

from alphafence.monitor.events import new_event
from alphafence.monitor.feeds import Feed, adsb, other_systems, telemetry_feeds


class FeedTasks:
    """The feeds of :class:`~alphafence.monitor.runner.Monitor` and their tasks."""

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
            position.skip = self._skip_raw
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
                self._wake.set()

        try:
            if feed.listen is not None:
                with feed.listen(pushed, **({} if feed.skip is None else {"skip": feed.skip})):
                    await asyncio.Event().wait()  # until cancelled
            async for value in feed.open():
                take(value)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            if feed.unavailable is None:
                raise
            self.log.put(new_event(feed.unavailable, error=str(exc)))

    def _ended_tasks(self):
        """A telemetry stream that ended (MAVSDK raised, or the stream closed) is an event,
        once: its value would otherwise go stale without a word. So is a live source's polling
        that ended (``source_ended``, alerted: it outlives whatever a server sends, so only a
        fault of the kit's own could end it)."""
        events = []
        for task in self.tasks:
            name = task.get_name()
            if not (name.startswith("telemetry:") or name == "source"):
                continue
            if task.done() and task not in self._ended and not task.cancelled():
                self._ended.add(task)
                exc = task.exception()
                error = "" if exc is None else f"{type(exc).__name__}: {exc}"
                kind = "source_ended" if name == "source" else "telemetry_task_ended"
                events.append(new_event(kind, task=name, error=" ".join(error.split())[:300]))
        return events
