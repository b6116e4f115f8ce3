"""Positions provably far from every fence, decided without asking the fences again.

After a full check that found the vehicle outside every fence (of any kind, at any altitude)
and at least ``keep_out_m`` from every keep-out in force, the triangle inequality bounds the
next positions: within ``clear_m`` of that point the vehicle is still outside every fence, and
its distance to the nearest keep-out is at least ``keep_out_m`` minus how far it has moved.
While that bound exceeds the look-ahead and the stopping margin, the full check could only
say CLEAR (no breach ahead within the look-ahead, nothing within the margin, inside nothing),
so :meth:`Clearance.assess` says it at the cost of one ``hypot``: most positions of a flight
away from fences touch no geometry at all, which is most of the monitor's CPU on a small
computer. Anything that changes what is in force (a time window opening, a new frame) changes
the fences' ``version`` and ends the shortcut; the engine uses it only while its level is
CLEAR, so no event can differ (``tests/test_monitor_clearance.py`` checks that property).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.awareness.predict import stopping_distance, time_to_breach
from alphafence.awareness.state import Assessment, Level


@dataclass(frozen=True)
class Clearance:
    """The room around one fully checked position.

    Attributes
    ----------
    x, y : float
        The position (metres, the fences' frame).
    clear_m : float
        Its distance to the nearest fence of any kind, in force or not (> 0: outside all).
    keep_out_m : float
        Its distance to the nearest keep-out in force, at any altitude (infinite when there
        is none).
    fence : int or None
        That keep-out's index.
    version : int
        The fences' ``version`` it was measured at.
    """

    x: float
    y: float
    clear_m: float
    keep_out_m: float
    fence: int | None
    version: int

    @classmethod
    def after(cls, fences, x: float, y: float, check) -> Clearance | None:
        """The clearance of a position whose full check is ``check``, or None when it is in
        or at a fence (or has left a keep-in): the next position is then checked in full."""
        if check.inside_keep_out or check.inside_warning or check.outside_keep_in:
            return None
        clear = fences.clearance(x, y)
        if not clear > 0.0:
            return None
        nearest = check.nearest_keep_out
        # at any altitude: the vehicle may climb or descend into a band before the next check
        keep_out = min(check.keep_out_any_m, nearest.distance_m if nearest else math.inf)
        return cls(x, y, clear, keep_out, nearest.index if nearest else None, fences.version)

    def assess(self, fences, x, y, speed_mps, lookahead_m, braking) -> Assessment | None:
        """CLEAR at ``(x, y)`` if this clearance proves it (see the module), else None."""
        if self.version != fences.version:
            return None
        moved = math.hypot(x - self.x, y - self.y)
        if not moved < self.clear_m:
            return None
        lower = self.keep_out_m - moved
        if not lower > max(lookahead_m, braking.margin_m):
            return None
        stop = stopping_distance(speed_mps, braking)
        return Assessment(
            Level.CLEAR, self.fence, lower, time_to_breach(None, speed_mps), stop, "clear"
        )
