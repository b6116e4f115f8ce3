"""One telemetry sample, the engine's input, and the checks that make it usable.

Examples
--------
>>> s = Sample(0.0, 35.9, 14.5, 20.0, vn=float("nan"))
>>> finite_velocity(s).vn, plausible(s), plausible(Sample(0.0, 0.0, 0.0, 0.0))
(0.0, True, False)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace


@dataclass
class Sample:
    """What the vehicle reported, as one input to :meth:`Engine.step`.

    The runner builds one from the latest value of each telemetry stream when a new position
    arrives; replay tests read them from recorded traces (``Sample(**json)``). ``alt_m`` and
    ``alt_amsl_m`` together place home AMSL: fences' limits are compared in their own
    reference (AMSL limits with ``alt_amsl_m``, AGL ones and others with ``alt_m``).
    """

    t: float  # seconds (monotonic)
    lat: float
    lon: float
    alt_m: float  # above home
    vn: float = 0.0  # m/s north
    ve: float = 0.0  # m/s east
    mode: str | None = None
    armed: bool | None = None
    alt_amsl_m: float | None = None  # AMSL: fences' AMSL limits, other aircraft's altitudes
    vd: float = 0.0  # m/s down
    gps_fix: int | None = None  # MAVLink GPS_FIX_TYPE (3 = 3D); None if unknown


def finite_velocity(s):
    """A velocity that is missing or not finite counts as zero: positions are still checked,
    only the prediction along the track is lost."""
    if all(isinstance(v, (int, float)) and math.isfinite(v) for v in (s.vn, s.ve, s.vd)):
        return s
    fix = lambda v: v if isinstance(v, (int, float)) and math.isfinite(v) else 0.0  # noqa: E731
    return replace(s, vn=fix(s.vn), ve=fix(s.ve), vd=fix(s.vd))


def plausible(s) -> bool:
    """Whether the position is finite, on the globe and not 0,0 (a GPS without a fix)."""
    ok = all(isinstance(v, (int, float)) and math.isfinite(v) for v in (s.lat, s.lon, s.alt_m))
    return ok and abs(s.lat) <= 90 and abs(s.lon) <= 180 and not (s.lat == 0 and s.lon == 0)
