"""What the monitor is told to do: the actions it may command and its options.

``alphafence monitor``'s flags become one :class:`MonitorOptions`, read by the engine (what to
predict and decide), the traffic watch and the runner (what to follow and fly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from alphafence.awareness.predict import Braking, stopping_distance
from alphafence.awareness.reach import DEFAULT_ACCEL_MPS2
from alphafence.awareness.traffic import TrafficOptions
from alphafence.errors import InputError
from alphafence.mavlink.storage import Profile
from alphafence.onboard import HOME_CLEARANCE_M

# the vehicle's own fence: watched as a layer, kept equal to the fences within reach and
# watched ("rolling": alphafence.monitor.rolling), or not
ONBOARD_MODES = ("watch", "rolling", "off")
REROUTE = "reroute"  # fly around the fence with the route planner (IMMINENT only)
ACTIONS = ("none", "brake", "rtl", "land", REROUTE)

NOT_REROUTE = (
    "re-routing is only an imminent action (a breach or a failsafe needs brake, rtl, land or none)"
)


@dataclass(frozen=True)
class RollingOptions:
    """How the rolling onboard fence (``--onboard rolling``) follows the vehicle.

    The *reach* is what the vehicle can cover in ``lookahead_s`` at ``speed_mps`` and then
    stop: ``speed_mps * lookahead_s + stopping_distance(speed_mps)``. The fence uploaded is
    compiled from the fences within ``radius_m`` of where the vehicle was: the reach, plus
    the hysteresis (a new fence only once the vehicle is ``hysteresis`` of the reach from
    that centre), plus what it flies during ``upload_budget_s`` while the next fence is
    compiled and uploaded. So the fence in force holds every fence within reach as long as a
    re-upload takes at most ``upload_budget_s``.

    Raises
    ------
    InputError
        For a speed, lookahead or budget that is not a number > 0 (budget >= 0), or a
        hysteresis outside (0, 1].

    Examples
    --------
    >>> o = RollingOptions()
    >>> round(o.reach_m(Braking())), round(o.trigger_m(Braking())), round(o.radius_m(Braking()))
    (337, 84, 471)
    """

    profile: Profile | None = None  # the vehicle's autopilot's default (copter; px4 on PX4)
    speed_mps: float = 10.0  # the vehicle's speed limit (ArduCopter's WPNAV_SPEED default)
    lookahead_s: float = 30.0
    hysteresis: float = 0.25  # re-centre after moving this fraction of the reach
    upload_budget_s: float = 5.0  # vehicle seconds a compile + upload + read-back may take
    retry_s: float = 2.0  # after a failed re-upload, wait this long before the next try
    home_clearance_m: float = HOME_CLEARANCE_M  # no compiled item this near home or the vehicle

    def __post_init__(self):
        for name, low in (("speed_mps", 0), ("lookahead_s", 0), ("retry_s", 0)):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= low:
                raise InputError(name, f"{v}: must be a number > {low}")
        b = self.upload_budget_s
        if not isinstance(b, (int, float)) or not math.isfinite(b) or b < 0:
            raise InputError("upload_budget_s", f"{b}: must be a number of seconds >= 0")
        h = self.hysteresis
        if not isinstance(h, (int, float)) or not 0 < h <= 1:
            raise InputError("hysteresis", f"{h}: must be a fraction of the reach in (0, 1]")

    def reach_m(self, braking: Braking) -> float:
        """Metres the vehicle can fly in the lookahead at its speed limit, then stop."""
        return self.speed_mps * self.lookahead_s + stopping_distance(self.speed_mps, braking)

    def trigger_m(self, braking: Braking) -> float:
        """How far from the centre of the fence in force a new fence is compiled."""
        return self.hysteresis * self.reach_m(braking)

    def radius_m(self, braking: Braking) -> float:
        """The fences within this distance of its centre make up a rolling fence."""
        return (
            self.reach_m(braking) + self.trigger_m(braking) + self.speed_mps * self.upload_budget_s
        )


@dataclass
class MonitorOptions:
    """How the monitor predicts, decides and acts (the ``alphafence monitor`` options).

    Raises
    ------
    InputError
        For a re-route asked for where only a stop will do (a breach or a failsafe), a
        re-route clearance that is not a number >= 0, or an onboard mode that is neither
        ``"watch"``, ``"rolling"`` nor ``"off"``.
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
    # the vehicle's acceleration at most: when the next full check is due far from fences
    max_accel_mps2: float = DEFAULT_ACCEL_MPS2
    traffic: TrafficOptions = field(default_factory=TrafficOptions)
    mavlink_traffic: bool = False  # other MAVLink systems' positions as traffic (ADS-B always)
    link_lost_s: float = 5.0  # no telemetry this long: the link is lost
    # what to command (with --enforce) on each failsafe event
    on_glitch: str = "none"
    on_stale: str = "none"
    on_link_lost: str = "none"
    # --imminent-action reroute: how far the re-route keeps from every keep-out fence
    reroute_clearance_m: float = 20.0
    # "watch": download the vehicle's own fence and check it as a layer of its own; "rolling":
    # also keep it equal to the fences within reach (re-uploaded in flight); "off"
    onboard: str = "watch"
    rolling: RollingOptions = field(default_factory=RollingOptions)  # --onboard rolling

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

    @property
    def watch_onboard(self) -> bool:
        """Does the monitor download the vehicle's fence and check it (``watch``, ``rolling``)?"""
        return self.onboard != "off"
