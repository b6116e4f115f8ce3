"""The monitor's decision engine: telemetry samples in, events out (alerts, level changes,
actions, failsafes). Synchronous and I/O-free, so it is unit-tested and replayed on recorded
traces; alphafence.monitor.runner feeds it from MAVSDK and carries out what it decides."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from alphafence.errors import InputError
from alphafence.monitor.fenceset import FenceSet
from alphafence.monitor.predict import Braking
from alphafence.monitor.state import Assessment, Level, StateMachine, assess
from alphafence.monitor.traffic import Traffic, TrafficOptions

REROUTE = "reroute"  # fly around the fence with the route planner (IMMINENT only)
ACTIONS = ("none", "brake", "rtl", "land", REROUTE)
REROUTE_FALLBACK = "brake"  # when no route (or no goal) exists
COMMAND_SETTLE_S = 3.0  # a mode change this soon after a monitor action is the monitor's own
# modes in which the pilot flies the vehicle (MAVSDK's names): switching into one of them, or
# out of a mode the monitor commanded, is the pilot taking over
PILOT_MODES = {"MANUAL", "ALTCTL", "POSCTL", "STABILIZED", "ACRO", "RATTITUDE"}
GLITCH_SLACK_M = 25.0  # telemetry arrival jitter must not look like a jump


@dataclass
class Sample:
    t: float  # seconds (monotonic)
    lat: float
    lon: float
    alt_m: float  # above home
    vn: float = 0.0  # m/s north
    ve: float = 0.0  # m/s east
    mode: str | None = None
    armed: bool | None = None
    alt_amsl_m: float | None = None  # for other aircraft, whose ADS-B altitudes are AMSL
    vd: float = 0.0  # m/s down
    gps_fix: int | None = None  # MAVLink GPS_FIX_TYPE (3 = 3D); None if unknown


@dataclass
class MonitorOptions:
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

    def __post_init__(self):
        for name in ("breach_action", "on_glitch", "on_stale", "on_link_lost"):
            if getattr(self, name) == REROUTE:
                flag = "--" + name.replace("_", "-")
                raise InputError(
                    "monitor",
                    f"{flag} {REROUTE}: re-routing is only an --imminent-action "
                    "(a breach or a failsafe needs brake, rtl, land or none)",
                )
        c = self.reroute_clearance_m
        if not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0:
            raise InputError("monitor", f"--reroute-clearance {c}: must be a number >= 0")

    @property
    def reroute(self) -> bool:
        return self.enforce and self.imminent_action == REROUTE


class Engine:
    def __init__(self, fences: FenceSet, options: MonitorOptions | None = None):
        self.fences = fences
        self.options = options or MonitorOptions()
        self.sm = StateMachine(self.options.hold_s)
        self.last: Sample | None = None
        self.last_t: float | None = None
        self.stale = False
        self.action_t = -math.inf  # when the monitor last commanded a mode
        self.in_commanded_mode = False
        self.expect_mode_change = False
        self.backoff_until = -math.inf
        self.checks = 0
        self.traffic = Traffic(self.options.traffic)
        self.conflicts: set = set()
        self.link_lost = False
        self.gps_degraded = False
        self.rerouting = False  # a re-route is being planned or flown (the runner's task)
        self.handing_back = False  # the next commanded mode change returns control

    # -- inputs ---------------------------------------------------------------------
    def step(self, s: Sample) -> list:
        s = _finite_velocity(s)
        events = []
        if s.gps_fix is not None and s.gps_fix < 3:
            if not self.gps_degraded:
                self.gps_degraded = True
                return self._failsafe(
                    s,
                    "gps_glitch",
                    self.options.on_glitch,
                    reason=f"GPS fix type {s.gps_fix} (no 3D fix)",
                )
            return []
        self.gps_degraded = False
        if not _plausible(s):
            return self._failsafe(
                s, "gps_glitch", self.options.on_glitch, reason="position missing, NaN or at 0,0"
            )
        if self.last is not None and s.t >= self.last.t:
            dt = s.t - self.last.t
            moved = _distance_m(self.last, s)
            if moved > self.options.max_speed_mps * dt + GLITCH_SLACK_M:
                why = f"position jumped {moved:.0f} m in {dt:.2f} s"
                return self._failsafe(s, "gps_glitch", self.options.on_glitch, reason=why)
        if self.stale:
            self.stale = False
            self.link_lost = False
            events.append(self._event(s.t, "telemetry_resumed", s))
        events += self._pilot(s)
        self.last, self.last_t = s, s.t
        x, y = self.fences.frame.to_local(s.lon, s.lat)
        speed = math.hypot(s.vn, s.ve)
        lookahead = max(50.0, speed * self.options.horizon_s)
        check = self.fences.check(float(x), float(y), s.alt_m, s.ve, s.vn, lookahead)
        self.checks += 1
        a = assess(check, speed, self.options.horizon_s, self.options.braking)
        if self.options.reroute:
            a = self._reroute_assessment(a, check)
        previous = self.sm.level
        level, changed = self.sm.update(a.level, s.t)
        if changed:
            events.append(
                self._event(
                    s.t,
                    "level",
                    s,
                    level=level.name,
                    previous=previous.name,
                    fence=self._site(a.fence),
                    distance_m=_r(a.distance_m),
                    time_to_breach_s=_r(a.time_to_breach_s),
                    stopping_m=_r(a.stopping_m),
                    reason=a.reason,
                )
            )
            events += self._act(s, level)
        events += self._traffic(s, float(x), float(y))
        return events

    def aircraft(self, key, t, lat, lon, alt_amsl_m, ve, vn, vu=0.0, callsign=""):
        """Another aircraft's report (ADS-B or another MAVLink system) for the dynamic fences."""
        from alphafence.monitor.traffic import Aircraft

        x, y = self.fences.frame.to_local(lon, lat)
        self.traffic.report(
            Aircraft(str(key), t, float(x), float(y), alt_amsl_m, ve, vn, vu, callsign)
        )

    def _traffic(self, s, x, y):
        if s.alt_amsl_m is None or not self.traffic.aircraft:
            return []
        found = self.traffic.conflicts(
            s.t, x, y, s.alt_amsl_m, s.ve, s.vn, -s.vd, self.options.horizon_s
        )
        events = []
        keys = {c.key for c in found}
        for c in found:
            if c.key not in self.conflicts:
                events.append(
                    self._event(
                        s.t,
                        "traffic_conflict",
                        s,
                        aircraft=c.key,
                        callsign=c.callsign,
                        t_cpa_s=_r(c.t_cpa_s),
                        separation_m=_r(c.horizontal_m),
                        vertical_m=_r(c.vertical_m),
                        radius_m=_r(c.radius_m),
                    )
                )
        for key in self.conflicts - keys:
            events.append(self._event(s.t, "traffic_clear", s, aircraft=key))
        self.conflicts = keys
        return events

    def tick(self, now: float) -> list:
        """Called on a timer: telemetry older than ``stale_s`` is an event, and older than
        ``link_lost_s`` the link is lost (each once, until telemetry resumes)."""
        if self.last_t is None:
            return []
        age = now - self.last_t
        if not self.stale and age > self.options.stale_s:
            self.stale = True
            return self._failsafe(
                self.last, "telemetry_stale", self.options.on_stale, t=now, age_s=round(age, 2)
            )
        if self.stale and not self.link_lost and age > self.options.link_lost_s:
            self.link_lost = True
            return self._failsafe(
                self.last, "link_lost", self.options.on_link_lost, t=now, age_s=round(age, 2)
            )
        return []

    def _failsafe(self, s, kind, action, t=None, **extra):
        t = s.t if t is None else t
        events = [self._event(t, kind, s, **extra)]
        if self.options.enforce and action != "none" and t >= self.backoff_until:
            events += self._command(t, s, action, reason=kind)
        return events

    # -- re-routing (the runner reports its progress) ---------------------------------
    def reroute_started(self, t, mode_change: bool = False, **extra) -> list:
        """The runner is about to fly a re-route: the vehicle now flies the monitor's
        commands (a mode change that is not the monitor's is the pilot taking over), and
        ``mode_change``: its first command switches the mode (to GUIDED)."""
        self.rerouting = True
        self.in_commanded_mode = True
        if mode_change:
            self._expect(t)
        return [self._event(t, "reroute", self.last, **extra)]

    def reroute_done(self, t, resume: bool = False, **extra) -> list:
        """The vehicle reached the re-route's goal; ``resume``: the runner now switches back
        to the mode it had (AUTO), which hands control back."""
        self.rerouting = False
        if resume:
            self._expect(t)
            self.handing_back = True
        else:
            self.in_commanded_mode = False
        return [self._event(t, "reroute_done", self.last, **extra)]

    def reroute_failed(self, t, reason, **extra) -> list:
        """No route (or no goal, or a leg not flown in time): brake instead."""
        self.rerouting = False
        s = self.last
        events = [self._event(t, "reroute_failed", s, reason=reason, **extra)]
        if not self.options.enforce:
            return events
        if t < self.backoff_until:
            return events + [
                self._event(
                    t,
                    "action_withheld",
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

    def _expect(self, t):
        """The monitor is about to command a mode change: it is not the pilot's."""
        self.action_t = t
        self.expect_mode_change = True

    def _command(self, t, s, action, **extra):
        """An action event; any other action ends a re-route in progress."""
        events = []
        if action == REROUTE:
            self.rerouting = True
        elif self.rerouting:
            self.rerouting = False
            events.append(self._event(t, "reroute_cancelled", s, reason=f"action {action}"))
        if action != REROUTE:  # a re-route tells when it changes the mode (reroute_started)
            self._expect(t)
        return events + [self._event(t, "action", s, action=action, **extra)]

    # -- decisions ------------------------------------------------------------------
    def _pilot(self, s):
        # the first mode known (telemetry streams start in any order) is not a change
        if s.mode is None or self.last is None or self.last.mode in (None, s.mode):
            return []
        if self.expect_mode_change and s.t - self.action_t <= COMMAND_SETTLE_S:
            self.expect_mode_change = False
            self.in_commanded_mode = not self.handing_back
            self.handing_back = False
            return []  # the mode change the monitor itself commanded
        self.handing_back = False
        overridden = self.in_commanded_mode
        self.in_commanded_mode = False
        if s.mode not in PILOT_MODES and not overridden:
            return []  # e.g. into GUIDED or AUTO: not the pilot taking the sticks
        # the pilot took over (or undid the monitor's action): do not fight them for a while
        self.backoff_until = s.t + self.options.backoff_s
        events = [
            self._event(s.t, "pilot_mode_change", s, mode=s.mode, backoff_s=self.options.backoff_s)
        ]
        if self.rerouting:  # the pilot flies now: the runner stops the re-route
            self.rerouting = False
            events.append(self._event(s.t, "reroute_cancelled", s, reason="pilot changed mode"))
        return events

    def _act(self, s, level):
        o = self.options
        if level == Level.IMMINENT:
            action = o.imminent_action
        elif level == Level.BREACH:
            action = o.breach_action
        else:
            return []
        if not o.enforce or action == "none":
            return []
        if s.t < self.backoff_until:
            return [
                self._event(
                    s.t, "action_withheld", s, action=action, reason="pilot changed mode recently"
                )
            ]
        if s.armed is False:
            return []
        if action == REROUTE and self.rerouting:
            return []  # one re-route at a time: the one under way already turns away
        return self._command(s.t, s, action)

    def _site(self, index):
        return None if index is None else self.fences.records[index].site_id

    def _event(self, t, kind, s, **extra):
        where = {}
        if s is not None:
            where = {"lat": _r(s.lat, 7), "lon": _r(s.lon, 7), "alt_m": _r(s.alt_m)}
        return {"time": round(t, 3), "event": kind, **where, **extra}


def _r(v, digits=2):
    """Rounded for the log; None for what is missing or not finite (the log is strict JSON)."""
    try:
        return None if v is None or not math.isfinite(v) else round(float(v), digits)
    except TypeError:
        return None


def _finite_velocity(s):
    """A velocity that is missing or not finite counts as zero: positions are still checked,
    only the prediction along the track is lost."""
    if all(isinstance(v, (int, float)) and math.isfinite(v) for v in (s.vn, s.ve, s.vd)):
        return s
    fix = lambda v: v if isinstance(v, (int, float)) and math.isfinite(v) else 0.0  # noqa: E731
    return replace(s, vn=fix(s.vn), ve=fix(s.ve), vd=fix(s.vd))


def _plausible(s) -> bool:
    ok = all(isinstance(v, (int, float)) and math.isfinite(v) for v in (s.lat, s.lon, s.alt_m))
    return ok and abs(s.lat) <= 90 and abs(s.lon) <= 180 and not (s.lat == 0 and s.lon == 0)


def _distance_m(a, b) -> float:
    dlat = math.radians(b.lat - a.lat)
    dlon = math.radians(b.lon - a.lon) * math.cos(math.radians(0.5 * (a.lat + b.lat)))
    return 6_371_000.0 * math.hypot(dlat, dlon)


def alert_text(event) -> str | None:
    """A STATUSTEXT (<= 50 characters) for the ground station, or None."""
    kind = event["event"]
    if kind == "level":
        text = f"AF {event['level']} {event.get('fence') or ''}"
        if event.get("time_to_breach_s") is not None and event["level"] in ("WARNING", "IMMINENT"):
            text += f" {event['time_to_breach_s']:.0f}s"
        return text[:50]
    if kind == "traffic_conflict":
        who = event.get("callsign") or event["aircraft"]
        return f"AF TRAFFIC {who} CPA {event['t_cpa_s']:.0f}s {event['separation_m']:.0f}m"[:50]
    if kind in ("gps_glitch", "telemetry_stale", "link_lost", "action", "action_withheld"):
        return f"AF {kind} {event.get('action', '')}".strip()[:50]
    if kind == "reroute":
        n = len(event.get("waypoints") or ())
        return f"AF REROUTE {n} wp {event.get('length_m') or 0:.0f} m"[:50]
    if kind in ("reroute_failed", "reroute_done", "reroute_cancelled"):
        return f"AF {kind}"
    return None
