"""The engine's lazy check: a position the last full check still proves CLEAR is not checked
again (:mod:`alphafence.awareness.reach` says which); a mixin of
:class:`~alphafence.monitor.engine.Engine`, which asks :meth:`LazyChecks.skip` first in
each step and :meth:`LazyChecks._reach` after each full check.

``tests/test_monitor_reach.py`` drives an engine with it and one that checks every position
with the same random flights and fences and asserts the same events at the same positions.
"""

from __future__ import annotations

from dataclasses import replace

from alphafence.awareness.clearance import Clearance
from alphafence.awareness.reach import Reach, due_s, read_scale
from alphafence.awareness.sample import Sample

GLITCH_SLACK_M = 25.0  # telemetry arrival jitter must not look like a jump
LOOKAHEAD_MIN_M = 50.0  # the look-ahead along the track at any speed
HOME_DRIFT_M = 1.0  # home's AMSL may move this much between full checks (AMSL bands)


class LazyChecks:
    """What the engine needs to skip the checks that cannot matter (see the module)."""

    def skip(self, t, lat, lon, alt, vn, ve) -> bool:
        """Whether a position needs no check: the last full check still proves it CLEAR, and
        nothing but the position changed since (the runner calls :meth:`invalidate` when the
        mode, armed state or GPS fix changes). When True it is counted in ``checks`` as a
        step would count it, and nothing else is to be done for it.

        The arguments are those of :meth:`Reach.holds <alphafence.awareness.reach.Reach.holds>`.
        """
        r = self.reach
        if r is None or r.version != self.fences.version or self.stale:
            return False
        if not r.holds(t, lat, lon, alt, vn, ve):
            return False
        self.last_t, self._skipped = t, (t, lat, lon, alt, vn, ve)
        self.checks += 1
        return True

    def invalidate(self) -> None:
        """Something besides the position changed (the mode, the armed state, the GPS fix,
        another aircraft): the next position is checked in full."""
        self.reach = None

    @property
    def last(self) -> Sample | None:
        """The latest position stepped (or skipped: :meth:`skip`), as a Sample."""
        k = self._skipped
        if k is not None and self._last is not None:
            self._skipped, s = None, self._last
            amsl = None if s.alt_amsl_m is None else s.alt_amsl_m + k[3] - s.alt_m
            self._last = replace(s, t=k[0], lat=k[1], lon=k[2], alt_m=k[3], vn=k[4], ve=k[5],
                                 alt_amsl_m=amsl)  # fmt: skip
        return self._last

    @last.setter
    def last(self, s: Sample | None) -> None:
        self._last, self._skipped = s, None

    def _reach(self, s, x, y, speed, check) -> Reach | None:
        """What this CLEAR full check proves for the positions after it, or None."""
        if self.options.reroute or self.traffic.aircraft or self.stale:
            return None
        scale = read_scale(s.lat)
        c = Clearance.after(self.fences, x, y, s.alt_m, check) if scale else None
        layer = self.onboard.index if self.onboard is not None else None
        if c is not None and layer is not None:
            c = c.join(Clearance.after(layer, x, y, s.alt_m, self.onboard.last_check))
        if c is None:
            return None
        o = self.options
        needed = max(LOOKAHEAD_MIN_M, o.braking.margin_m)
        accel = o.max_accel_mps2
        due = due_s(speed, accel, c.room_m, c.keep_out_m, needed, o.horizon_s, scale)
        if not due > 0.0:
            return None
        jacobian = self.fences.frame.jacobian(s.lon, s.lat)
        return Reach(s.t, s.lat, s.lon, s.alt_m, speed, accel, jacobian, due, scale, o.stale_s,
                     c.vertical_m - HOME_DRIFT_M, (o.max_speed_mps, GLITCH_SLACK_M),
                     self.fences.version, (s.mode, s.armed, s.gps_fix))  # fmt: skip
