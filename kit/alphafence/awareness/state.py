"""The monitor's alert levels, with hysteresis: escalate at once, relax only after the
condition has been clear for ``hold_s`` seconds (no flapping at a fence edge)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

from alphafence.awareness.predict import Braking, stopping_distance, time_to_breach


class Level(IntEnum):
    """The monitor's alert levels, ordered: a higher one is worse."""

    CLEAR = 0
    WARNING = 1
    IMMINENT = 2
    BREACH = 3


@dataclass
class Assessment:
    """One position's raw level, the fence it concerns and why."""

    level: Level
    fence: int | None
    distance_m: float
    time_to_breach_s: float
    stopping_m: float
    reason: str


def assess(check, speed_mps, horizon_s, braking: Braking = None) -> Assessment:
    """One position's raw level (before hysteresis)."""
    braking = braking or Braking()
    stop = stopping_distance(speed_mps, braking)
    nearest = check.nearest_keep_out
    dist = nearest.distance_m if nearest else math.inf
    if check.inside_keep_out:
        return Assessment(
            Level.BREACH, check.inside_keep_out[0], 0.0, 0.0, stop, "inside a keep-out fence"
        )
    if check.outside_keep_in:
        return Assessment(
            Level.BREACH, check.outside_keep_in[0], 0.0, 0.0, stop, "outside the keep-in fence"
        )
    ahead = check.breach_ahead
    ttb = time_to_breach(ahead[1] if ahead else None, speed_mps)
    if ahead and stop >= ahead[1]:
        return Assessment(
            Level.IMMINENT, ahead[0], ahead[1], ttb, stop, "cannot stop before the fence ahead"
        )
    if dist <= braking.margin_m:
        return Assessment(Level.IMMINENT, nearest.index, dist, ttb, stop, "at the fence margin")
    if ahead and ttb <= horizon_s:
        return Assessment(
            Level.WARNING, ahead[0], ahead[1], ttb, stop, f"breach predicted in {ttb:.1f} s"
        )
    if check.inside_warning:
        return Assessment(
            Level.WARNING, check.inside_warning[0], dist, ttb, stop, "inside a warning layer"
        )
    return Assessment(Level.CLEAR, nearest.index if nearest else None, dist, ttb, stop, "clear")


@dataclass
class StateMachine:
    """The alert level with hysteresis: up at once, down after ``hold_s`` of calm."""

    hold_s: float = 2.0
    level: Level = Level.CLEAR
    _calm_since: float | None = field(default=None, repr=False)

    def update(self, raw: Level, now: float):
        """Returns (new level, changed)."""
        if raw >= self.level:
            changed = raw != self.level
            self.level = raw
            self._calm_since = None
            return self.level, changed
        if self._calm_since is None:
            self._calm_since = now
        if now - self._calm_since >= self.hold_s:
            self.level = raw
            self._calm_since = None
            return self.level, True
        return self.level, False
