"""The monitor's decision engine: telemetry samples in, events out (alerts, level changes,
actions, failsafes). Synchronous and I/O-free, so it is unit-tested and replayed on recorded
traces; kit.monitor.runner feeds it from MAVSDK and carries out what it decides."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from kit.monitor.fenceset import FenceSet
from kit.monitor.predict import Braking
from kit.monitor.state import Level, StateMachine, assess
from kit.monitor.traffic import Traffic, TrafficOptions

ACTIONS = ("none", "brake", "rtl", "land")
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

    # -- inputs ---------------------------------------------------------------------
    def step(self, s: Sample) -> list:
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
        from kit.monitor.traffic import Aircraft

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
            self.action_t = t
            self.expect_mode_change = True
            events.append(self._event(t, "action", s, action=action, reason=kind))
        return events

    # -- decisions ------------------------------------------------------------------
    def _pilot(self, s):
        if s.mode is None or self.last is None or s.mode == self.last.mode:
            return []
        if self.expect_mode_change and s.t - self.action_t <= COMMAND_SETTLE_S:
            self.expect_mode_change = False
            self.in_commanded_mode = True
            return []  # the mode change the monitor itself commanded
        overridden = self.in_commanded_mode
        self.in_commanded_mode = False
        if s.mode not in PILOT_MODES and not overridden:
            return []  # e.g. into GUIDED or AUTO: not the pilot taking the sticks
        # the pilot took over (or undid the monitor's action): do not fight them for a while
        self.backoff_until = s.t + self.options.backoff_s
        return [
            self._event(s.t, "pilot_mode_change", s, mode=s.mode, backoff_s=self.options.backoff_s)
        ]

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
        self.action_t = s.t
        self.expect_mode_change = True
        return [self._event(s.t, "action", s, action=action)]

    def _site(self, index):
        return None if index is None else self.fences.records[index].site_id

    def _event(self, t, kind, s, **extra):
        return {
            "time": round(t, 3),
            "event": kind,
            "lat": round(s.lat, 7),
            "lon": round(s.lon, 7),
            "alt_m": _r(s.alt_m),
            **extra,
        }


def _r(v):
    return None if v is None or not math.isfinite(v) else round(float(v), 2)


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
    return None
