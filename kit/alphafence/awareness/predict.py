"""Prediction arithmetic: stopping distance, time to breach, closest point of approach."""

from __future__ import annotations

import math
from dataclasses import dataclass

VERTICAL_MARGIN_M = 10.0  # altitude error (GPS, baro, home) kept above and below a fence's band


@dataclass(frozen=True)
class Braking:
    """How the vehicle stops: reaction time, deceleration, and the margin kept at the end."""

    reaction_s: float = 1.5  # link + decision + autopilot mode change and response
    decel_mps2: float = 2.5  # a Copter in BRAKE decelerates at a few m/s²
    margin_m: float = 2.0


def stopping_distance(speed_mps: float, braking: Braking = None) -> float:
    """Metres covered before standstill: reaction time at speed, then constant braking."""
    braking = braking or Braking()
    v = max(0.0, speed_mps)
    return v * braking.reaction_s + v * v / (2.0 * braking.decel_mps2) + braking.margin_m


def time_to_breach(distance_along_track_m: float | None, speed_mps: float) -> float:
    """Seconds until the track reaches the fence at the current speed (inf if never)."""
    if distance_along_track_m is None or speed_mps <= 0.05:
        return math.inf
    return distance_along_track_m / speed_mps


def vertical_reach(vd_mps: float, horizon_s: float, margin_m: float = VERTICAL_MARGIN_M) -> float:
    """Metres the vehicle may climb or descend within the horizon at its vertical speed, plus
    a margin: the prediction counts the fences whose altitude band is within this of it.

    Examples
    --------
    >>> vertical_reach(0.0, 15.0), vertical_reach(-2.0, 15.0)
    (10.0, 40.0)
    """
    vd = abs(vd_mps) if math.isfinite(vd_mps) else 0.0
    return vd * max(0.0, horizon_s) + margin_m


def closest_approach(rx, ry, rz, vx, vy, vz, horizon_s):
    """Time (clamped to [0, horizon]) and distance of closest approach between two craft with
    relative position r (other minus own, metres) and relative velocity v (m/s)."""
    vv = vx * vx + vy * vy + vz * vz
    t = 0.0 if vv < 1e-9 else -(rx * vx + ry * vy + rz * vz) / vv
    t = min(max(t, 0.0), horizon_s)
    dx, dy, dz = rx + vx * t, ry + vy * t, rz + vz * t
    return t, math.sqrt(dx * dx + dy * dy + dz * dz)


def dynamic_radius(base_m: float, closing_speed_mps: float, reaction_s: float = 2.0) -> float:
    """A moving aircraft's keep-out cylinder grows with how fast the two close on each other."""
    return base_m + max(0.0, closing_speed_mps) * reaction_s
