"""What the monitor is told to do: the actions it may command and its options.

``alphafence monitor``'s flags become one :class:`MonitorOptions`, read by the engine (what to
predict and decide), the traffic watch and the runner (what to follow and fly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from alphafence.errors import InputError
from alphafence.monitor.predict import Braking
from alphafence.monitor.traffic import TrafficOptions

ONBOARD_MODES = ("watch", "off")  # the vehicle's own fence: watched as a layer, or not
REROUTE = "reroute"  # fly around the fence with the route planner (IMMINENT only)
ACTIONS = ("none", "brake", "rtl", "land", REROUTE)

NOT_REROUTE = (
    "re-routing is only an imminent action (a breach or a failsafe needs brake, rtl, land or none)"
)


@dataclass
class MonitorOptions:
    """How the monitor predicts, decides and acts (the ``alphafence monitor`` options).

    Raises
    ------
    InputError
        For a re-route asked for where only a stop will do (a breach or a failsafe), a
        re-route clearance that is not a number >= 0, or an onboard mode that is neither
        ``"watch"`` nor ``"off"``.
    """

    horizon_s: float = 15.0
    braking: Braking = field(default_factory=Braking)
    enforce: bool = False
    imminent_action: str = "brake"
    breach_action: str = "rtl"
    hold_s: float = 2.0  # hysteresis
    backoff_s: float = 15.0  # after the pilot changes mode, alert only
    stale_s: float = 1.0
    max_speed_mps: float = 60.0  # a position jump faster than this is a GPS glitch
    traffic: TrafficOptions = field(default_factory=TrafficOptions)
    mavlink_traffic: bool = False  # other MAVLink systems' positions as traffic (ADS-B always)
    link_lost_s: float = 5.0  # no telemetry this long: the link is lost
    # what to command (with --enforce) on each failsafe event
    on_glitch: str = "none"
    on_stale: str = "none"
    on_link_lost: str = "none"
    # --imminent-action reroute: how far the re-route keeps from every keep-out fence
    reroute_clearance_m: float = 20.0
    # "watch": download the vehicle's own fence and check it as a layer of its own; "off"
    onboard: str = "watch"

    def __post_init__(self):
        for name in ("breach_action", "on_glitch", "on_stale", "on_link_lost"):
            if getattr(self, name) == REROUTE:
                raise InputError(name, f"{REROUTE}: {NOT_REROUTE}")
        if self.onboard not in ONBOARD_MODES:
            raise InputError(
                "onboard", f"{self.onboard!r}: must be one of {', '.join(ONBOARD_MODES)}"
            )
        c = self.reroute_clearance_m
        if not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0:
            raise InputError("reroute_clearance_m", f"{c}: must be a number of metres >= 0")

    @property
    def reroute(self) -> bool:
        """Does the monitor fly re-routes (``--enforce --imminent-action reroute``)?"""
        return self.enforce and self.imminent_action == REROUTE
