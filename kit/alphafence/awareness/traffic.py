"""Dynamic fences around other aircraft (ADSB_VEHICLE reports, other MAVLink systems).

Each aircraft becomes a vertical cylinder around its predicted track whose radius grows with
how fast it and the own vehicle close on each other; a conflict is predicted from the closest
point of approach (CPA) within the horizon. Reports older than ``stale_s`` are dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.awareness.predict import closest_approach, dynamic_radius


@dataclass
class Aircraft:
    """Another aircraft's latest report, in the monitor's frame."""

    key: str  # ICAO address or MAVLink system id
    t: float  # monotonic seconds of the report
    x: float  # metres east in the monitor's frame
    y: float  # metres north
    alt_m: float
    ve: float  # m/s east
    vn: float  # m/s north
    vu: float = 0.0  # m/s up
    callsign: str = ""


@dataclass(frozen=True)
class TrafficOptions:
    """The size of the cylinder around other aircraft and how long a report lasts."""

    horizontal_m: float = 150.0  # base radius of the cylinder
    vertical_m: float = 50.0  # half height
    reaction_s: float = 2.0  # the radius grows by closing speed times this
    stale_s: float = 10.0


@dataclass
class Conflict:
    """A predicted loss of separation with one aircraft."""

    key: str
    callsign: str
    t_cpa_s: float
    horizontal_m: float  # separation at the CPA
    vertical_m: float
    radius_m: float  # the cylinder radius it was judged against
    now: bool  # already inside the cylinder


class Traffic:
    """The other aircraft around the vehicle and the conflicts they are in with it.

    Parameters
    ----------
    options : TrafficOptions, optional
        The defaults if omitted.
    """

    def __init__(self, options: TrafficOptions | None = None):
        self.options = options or TrafficOptions()
        self.aircraft: dict = {}

    def report(self, a: Aircraft):
        """Keep ``a`` as its aircraft's latest report (an older one than that kept is ignored)."""
        old = self.aircraft.get(a.key)
        if old is None or a.t >= old.t:
            self.aircraft[a.key] = a

    def conflicts(self, now, x, y, alt_m, ve, vn, vu=0.0, horizon_s=30.0) -> list:
        """The aircraft the vehicle is, or within ``horizon_s`` will be, in conflict with.

        Each aircraft is dead-reckoned from its report to ``now``; reports older than
        ``stale_s`` are dropped on the way.

        Parameters
        ----------
        now : float
            Monotonic seconds, as the reports' ``t``.
        x, y, alt_m : float
            The vehicle: metres east and north in the monitor's frame, metres AMSL.
        ve, vn, vu : float
            Its velocity, m/s east, north and up.
        horizon_s : float
            How far ahead to predict.

        Returns
        -------
        list of Conflict
            Soonest closest approach first.
        """
        o = self.options
        out = []
        for key in list(self.aircraft):
            a = self.aircraft[key]
            age = now - a.t
            if age > o.stale_s:
                del self.aircraft[key]
                continue
            # where the other aircraft is now, dead-reckoned from its report
            ax, ay, az = a.x + a.ve * age, a.y + a.vn * age, a.alt_m + a.vu * age
            rx, ry, rz = ax - x, ay - y, az - alt_m
            vx, vy, vz = a.ve - ve, a.vn - vn, a.vu - vu
            dist = math.hypot(rx, ry)
            closing = -(rx * vx + ry * vy) / dist if dist > 1e-6 else math.hypot(vx, vy)
            radius = dynamic_radius(o.horizontal_m, closing, o.reaction_s)
            t, _ = closest_approach(rx, ry, 0.0, vx, vy, 0.0, horizon_s)
            hx, hy = rx + vx * t, ry + vy * t
            h_sep = math.hypot(hx, hy)
            v_sep = abs(rz + vz * t)
            if h_sep <= radius and v_sep <= o.vertical_m:
                out.append(
                    Conflict(key, a.callsign, t, h_sep, v_sep, radius, t == 0.0 or dist <= radius)
                )
        out.sort(key=lambda c: c.t_cpa_s)
        return out
