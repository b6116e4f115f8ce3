"""A recorded flight replayed at its own pace on the event loop, as the monitor would have
seen it, with observers: what the live map (:mod:`alphafence.livemap.observer`) shows during
``alphafence demo --replay --map-server``.

:func:`~alphafence.review.replay.replay` steps a trace as fast as it can; :func:`replay_live`
waits for each sample's time (the trace's times, from its first sample, divided by ``pace``)
and, like the monitor's runner, steps on the latest sample due: samples that came due while
the event loop was busy elsewhere are coalesced into it (counted), so a busy loop shows as
fewer steps.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field

from alphafence.monitor.engine import Engine
from alphafence.monitor.events import UtcClock
from alphafence.monitor.observe import Step


@dataclass
class LiveReplay:
    """What a :func:`replay_live` did.

    Attributes
    ----------
    engine : Engine
        The engine it stepped (``engine.checks``).
    events : list of dict
        Every event, in order, stamped with the replay's UTC.
    steps : int
        Engine steps.
    coalesced : int
        Samples that came due while the event loop was busy, stepped over (their latest was
        stepped instead).
    stopped : bool
        Ended by ``stop`` before the last sample.
    """

    engine: Engine
    events: list = field(default_factory=list)
    steps: int = 0
    coalesced: int = 0
    stopped: bool = False


async def replay_live(
    trace,
    fences,
    options=None,
    observers=(),
    clock: UtcClock | None = None,
    stop: asyncio.Event | None = None,
    echo=None,
    pace: float = 1.0,
    **fields,
) -> LiveReplay:
    """Replay ``trace`` in real time (divided by ``pace``) through a fresh engine, telling
    ``observers`` of the engine, every step and every event.

    Parameters
    ----------
    trace : Trace
        The recorded flight (:class:`~alphafence.review.replay.Trace`).
    fences : FenceSet
        The full-resolution fences.
    options : MonitorOptions, optional
        As for :func:`~alphafence.review.replay.replay`.
    observers : sequence of Observer
        Told as the monitor's observers are (:mod:`alphafence.monitor.observe`).
    clock : UtcClock, optional
        The events' UTC (default the trace's).
    stop : asyncio.Event, optional
        Ends the replay early when set.
    echo : callable, optional
        Called with every event (before the observers).
    pace : float
        How many times faster than recorded (1: as recorded).
    **fields
        Added to every event (e.g. ``replay=True``).

    Returns
    -------
    LiveReplay
    """
    clock = clock or trace.utc_clock()
    engine = Engine(fences, options)
    for o in observers:
        if hasattr(o, "on_engine"):
            o.on_engine(engine)
    out = LiveReplay(engine)

    def handle(event):
        event = {**clock.stamp(event), **fields}
        out.events.append(event)
        if echo is not None:
            echo(event)
        for o in observers:
            o.on_event(event)

    samples = trace.samples
    if not samples:
        return out
    t0 = samples[0].t
    if engine.options.onboard == "watch" and trace.onboard_items:
        for e in engine.load_onboard(trace.onboard_items, t=t0, cause="start"):
            handle(e)
    loop = asyncio.get_running_loop()
    start = loop.time()

    def due(k):
        return start + (samples[k].t - t0) / pace

    i = 0
    while i < len(samples):
        wait = due(i) - loop.time()
        if stop is not None and stop.is_set():
            out.stopped = True
            break
        if wait > 0:
            if stop is None:
                await asyncio.sleep(wait)
            else:
                try:
                    await asyncio.wait_for(stop.wait(), wait)
                except asyncio.TimeoutError:
                    pass
                if stop.is_set():
                    out.stopped = True
                    break
        now, j = loop.time(), i
        while j + 1 < len(samples) and due(j + 1) <= now:
            j += 1
        out.coalesced += j - i
        sample, i = samples[j], j + 1
        started, checks = time.monotonic(), engine.checks
        events = engine.step(sample)
        out.steps += 1
        step = Step(sample, started, engine.checks > checks, engine.sm.level, tuple(events))
        for o in observers:
            o.on_step(step)
        for e in events:
            handle(e)
    return out
