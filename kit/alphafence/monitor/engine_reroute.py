"""The engine's re-route decisions (``--imminent-action reroute``): IMMINENT early enough to
turn away, and what the runner reports while it plans and flies a re-route
(:mod:`alphafence.monitor.reroute_flight`). A part of :class:`~alphafence.monitor.engine.Engine`,
kept here to keep the engine's module small."""

from __future__ import annotations

from alphafence.awareness.state import Assessment, Level
from alphafence.monitor.events import new_event

REROUTE_FALLBACK = "brake"  # when no route (or no goal) exists


class RerouteDecisions:
    """The :class:`~alphafence.monitor.engine.Engine`'s re-route methods (a mixin: the state
    they read and change is the engine's: ``rerouting``, ``in_commanded_mode``,
    ``handing_back``, ``last``, ``options``, ``backoff_until``)."""

    def reroute_started(self, t, mode_change: bool = False, **extra) -> list:
        """The runner is about to fly a re-route: the vehicle now flies the monitor's
        commands (a mode change that is not the monitor's is the pilot taking over), and
        ``mode_change``: its first command switches the mode (to GUIDED)."""
        self.rerouting = True
        self.in_commanded_mode = True
        if mode_change:
            self._expect(t)
        return [new_event("reroute", t, self.last, **extra)]

    def reroute_done(self, t, resume: bool = False, **extra) -> list:
        """The vehicle reached the re-route's goal; ``resume``: the runner now switches back
        to the mode it had (AUTO), which hands control back."""
        self.rerouting = False
        if resume:
            self._expect(t)
            self.handing_back = True
        else:
            self.in_commanded_mode = False
        return [new_event("reroute_done", t, self.last, **extra)]

    def reroute_failed(self, t, reason, **extra) -> list:
        """No route (or no goal, or a leg not flown in time): brake instead."""
        self.rerouting = False
        s = self.last
        events = [new_event("reroute_failed", t, s, reason=reason, **extra)]
        if not self.options.enforce:
            return events
        if t < self.backoff_until:
            return events + [
                new_event(
                    "action_withheld",
                    t,
                    s,
                    action=REROUTE_FALLBACK,
                    reason="pilot changed mode recently",
                )
            ]
        if s is not None and s.armed is False:
            return events
        return events + self._command(t, s, REROUTE_FALLBACK, reason="reroute_failed")

    def _reroute_assessment(self, a, check):
        """With re-routing, IMMINENT comes while the vehicle can still stop the re-route
        clearance short of the fence ahead: from there it can turn away and keep it."""
        ahead = check.breach_ahead
        if a.level >= Level.IMMINENT or ahead is None:
            return a
        clearance = self.options.reroute_clearance_m
        if a.stopping_m + clearance < ahead[1]:
            return a
        return Assessment(
            Level.IMMINENT,
            ahead[0],
            ahead[1],
            a.time_to_breach_s,
            a.stopping_m,
            f"cannot stop {clearance:g} m (the re-route clearance) before the fence ahead",
        )
