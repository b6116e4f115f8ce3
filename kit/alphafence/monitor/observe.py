"""Watching a running monitor from outside: every value its feeds deliver, every engine step,
every event.

Benchmarks and tests observe the monitor through an :class:`Observer` (``Monitor(...,
observers=[...])`` or :meth:`Monitor.add_observer <alphafence.monitor.runner.Monitor>`),
never by overriding its methods. Observers are called on the event loop, synchronously, in
the order things happen: a step is observed before the events it returned, and those before
the next step. They must return quickly, must not raise (the exception would reach the part
of the monitor that called them) and must not change what they are given.
"""

from __future__ import annotations

from dataclasses import dataclass

from alphafence.awareness.state import Level
from alphafence.monitor.engine import Sample


@dataclass(frozen=True)
class Step:
    """One engine step: the sample the runner checked and what the engine made of it.

    Attributes
    ----------
    sample : Sample
        What was stepped; ``sample.t`` is when its position arrived (``time.monotonic()``).
    started : float
        When the step began (``time.monotonic()``): ``started - sample.t`` is how long the
        position waited, and positions that arrived in between were coalesced into it.
    checked : bool
        The step checked the position against the fences (False: it stopped at the GPS
        glitch or no-fix test).
    level : Level
        The alert level after the step.
    events : tuple of dict
        The events the step returned, which the observers see next.
    known : bool
        What is in force is known (False: a monitor started from a live source alone, before
        its first complete answer; its level is then not reported CLEAR).
    """

    sample: Sample
    started: float
    checked: bool
    level: Level
    events: tuple
    known: bool = True


class Observer:
    """Base class for observers of a :class:`~alphafence.monitor.runner.Monitor`: override
    what you need, the rest does nothing.

    Examples
    --------
    >>> class Counter(Observer):
    ...     def __init__(self):
    ...         self.positions = 0
    ...
    ...     def on_value(self, stream, t, value):
    ...         self.positions += stream == "position"
    """

    def on_engine(self, engine) -> None:
        """The engine the observed monitor decides with, once, when the observer is added:
        read what it holds (``engine.onboard``: the vehicle's fence; ``engine.options``),
        never change it."""

    def on_value(self, stream: str, t: float, value) -> None:
        """A feed delivered ``value`` at ``t`` (``time.monotonic()``).

        Parameters
        ----------
        stream : str
            ``"position"``, ``"velocity"``, ``"mode"``, ``"armed"``, ``"gps"`` (MAVSDK's
            telemetry values, as they are); ``"adsb"`` and ``"traffic"`` (each usable report,
            as :meth:`Engine.aircraft <alphafence.monitor.engine.Engine.aircraft>` keyword
            arguments); ``"target"`` (the GUIDED target, ``(lon, lat)``) and
            ``"mission_progress"`` (``(current, total)``) while re-routing is on.
        t : float
            When it arrived; a position's ``t`` becomes its sample's ``t``.
        value : object
            What arrived.
        """

    def on_step(self, step: Step) -> None:
        """The engine stepped on a sample (see :class:`Step`)."""

    def on_event(self, event: dict) -> None:
        """An event was put in the event log (the engine's, and the runner's own:
        ``action_done``, ``alert_failed``, ``adsb_unavailable``, ``log_write_failed``,
        ``onboard_fence``, ``onboard_failed``, ...)."""


class UntilDisarmed(Observer):
    """Set ``stop`` once the vehicle, having been armed, is disarmed: the flight is over (it
    landed, or was disarmed by hand).

    Parameters
    ----------
    stop : asyncio.Event
        The monitor's stop event.

    Examples
    --------
    >>> import asyncio
    >>> stop = asyncio.Event()
    >>> watch = UntilDisarmed(stop)
    >>> for armed in (False, True, True, False):
    ...     watch.on_value("armed", 0.0, armed)
    >>> stop.is_set(), watch.flown
    (True, True)
    """

    def __init__(self, stop):
        self.stop = stop
        self.flown = False

    def on_value(self, stream: str, t: float, value) -> None:
        if stream != "armed" or value is None:
            return
        if value:
            self.flown = True
        elif self.flown:
            self.stop.set()
