"""The monitor's decision engine: telemetry samples in, events out (alerts, level changes,
actions, failsafes). Synchronous and I/O-free, so it is unit-tested and replayed on recorded
traces; alphafence.monitor.runner feeds it from MAVSDK and carries out what it decides.
Events are built by alphafence.monitor.events (their alert texts too)."""

from __future__ import annotations

import math

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import vertical_reach
from alphafence.awareness.sample import Sample, finite_velocity, plausible
from alphafence.awareness.state import Level, StateMachine, assess
from alphafence.awareness.traffic import Traffic
from alphafence.geo.frame import short_distance_m
from alphafence.mavlink.ids import GPS_FIX_TYPE_3D_FIX
from alphafence.monitor.engine_reach import GLITCH_SLACK_M, LOOKAHEAD_MIN_M, LazyChecks
from alphafence.monitor.engine_reroute import REROUTE_FALLBACK, RerouteDecisions
from alphafence.monitor.events import new_event, rounded
from alphafence.monitor.onboard import Decision, OnboardLayer, load_layer, unreadable
from alphafence.monitor.options import REROUTE, MonitorOptions

COMMAND_SETTLE_S = 3.0  # a mode change this soon after a monitor action is the monitor's own
# modes in which the pilot flies the vehicle (ArduPilot's names: Copter, Plane, Rover; PX4's
# as MAVSDK names them, none of which names another ArduPilot mode): switching into one of
# them, or out of a mode the monitor commanded, is the pilot taking over
PILOT_MODES = {
    *("STABILIZE", "ACRO", "ALT_HOLD", "POSHOLD", "SPORT", "DRIFT", "FLOWHOLD"),
    *("MANUAL", "TRAINING", "FBWA", "FBWB", "CRUISE", "QSTABILIZE", "QHOVER", "QACRO"),
    "STEERING",
    *("POSCTL", "ALTCTL", "STABILIZED"),  # PX4's Position, Altitude, Stabilized (and ACRO, MANUAL)
}


class Engine(RerouteDecisions, LazyChecks):
    """The monitor's decisions, fed one telemetry sample (:meth:`step`) or timer tick
    (:meth:`tick`) at a time; every call returns the events it decided (dicts, see
    :mod:`alphafence.monitor.events`). ``checks`` counts the positions checked against the
    fences; ``sm.level`` is the current alert level.

    Parameters
    ----------
    fences : FenceSet
        Every fence, indexed.
    options : MonitorOptions, optional
        The defaults if omitted.
    """

    def __init__(self, fences: FenceSet, options: MonitorOptions | None = None):
        self.fences = fences
        self.options = options or MonitorOptions()
        self.sm = StateMachine(self.options.hold_s)
        self._last: Sample | None = None
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
        self.onboard: OnboardLayer | None = None  # the fence the vehicle holds (load_onboard)
        self.shortcut = True  # positions a full check still proves CLEAR are not checked again
        self.reach = None  # what the last full check proves, and until when (a Reach)
        self.full_checks = 0  # positions checked against the fences in full
        self._skipped = None  # the last position :meth:`skip` took, when newer than ``last``
        self.amsl_said = False  # whether AMSL limits without an altitude AMSL were said

    # -- inputs ---------------------------------------------------------------------
    def step(self, s: Sample) -> list:
        """Decide on one telemetry sample.

        In order: a GPS without a 3D fix, an implausible position or a jump faster than
        ``max_speed_mps`` is a ``gps_glitch`` (and the sample goes no further); telemetry back
        after a stale spell is ``telemetry_resumed``; a mode change that is not the monitor's
        own is the pilot taking over (``pilot_mode_change``, then alert only for
        ``backoff_s``); then the position is checked against every fence along the track
        (``checks`` counts these) and against the vehicle's own fence (:meth:`load_onboard`),
        the worse level passes the hysteresis and a change of level is a ``level`` event
        (when the vehicle's fence raised it: ``onboard`` and ``items`` name its item, and
        ``onboard_only`` says no full-resolution fence is there) followed by the action it
        calls for (``action`` or ``action_withheld``, with ``enforce``); last, other aircraft in conflict
        (``traffic_conflict``, ``traffic_clear``).

        Parameters
        ----------
        s : Sample
            The vehicle's latest position, velocity, mode, armed state and GPS fix; ``s.t``
            must not go backwards (monotonic seconds).

        Returns
        -------
        list of dict
            The events, in the order they happened (empty when nothing changed).
        """
        s = finite_velocity(s)
        r = self.reach
        if (
            r is not None
            and r.stamp == (s.mode, s.armed, s.gps_fix)
            and self.skip(s.t, s.lat, s.lon, s.alt_m, s.vn, s.ve)
        ):
            self._skipped, self._last = None, s
            return []
        events = []
        if s.gps_fix is not None and s.gps_fix < GPS_FIX_TYPE_3D_FIX:
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
        if not plausible(s):
            return self._failsafe(
                s, "gps_glitch", self.options.on_glitch, reason="position missing, NaN or at 0,0"
            )
        if self.last is not None and s.t >= self.last.t:
            dt = s.t - self.last.t
            moved = short_distance_m((self.last.lat, self.last.lon), (s.lat, s.lon))
            if moved > self.options.max_speed_mps * dt + GLITCH_SLACK_M:
                why = f"position jumped {moved:.0f} m in {dt:.2f} s"
                return self._failsafe(s, "gps_glitch", self.options.on_glitch, reason=why)
        if self.stale:
            self.stale = False
            self.link_lost = False
            events.append(new_event("telemetry_resumed", s.t, s))
        events += self._pilot(s)
        events += self._home(s)
        self.last, self.last_t = s, s.t
        x, y = self.fences.frame.to_local(s.lon, s.lat)
        speed = math.hypot(s.vn, s.ve)
        lookahead = max(LOOKAHEAD_MIN_M, speed * self.options.horizon_s)
        x, y = float(x), float(y)
        vertical = vertical_reach(s.vd, self.options.horizon_s)
        check = self.fences.check(x, y, s.alt_m, s.ve, s.vn, lookahead, vertical)
        a = assess(check, speed, self.options.horizon_s, self.options.braking)
        if self.options.reroute:
            a = self._reroute_assessment(a, check)
        self.checks += 1
        self.full_checks += 1
        if self.onboard is None:
            d = Decision(a, full_level=a.level)
        else:  # the vehicle's own fence, as a layer of its own
            d = self.onboard.decide(
                a, self.fences, float(x), float(y), s.alt_m, s.ve, s.vn, lookahead, self.options
            )
            a = d.assessment
        previous = self.sm.level
        level, changed = self.sm.update(a.level, s.t)
        if changed:
            f = d.onboard
            events.append(
                new_event(
                    "level",
                    s.t,
                    s,
                    level=level.name,
                    previous=previous.name,
                    fence=self._site(a.fence) if f is None else d.site or f.name,
                    distance_m=rounded(a.distance_m),
                    time_to_breach_s=rounded(a.time_to_breach_s),
                    stopping_m=rounded(a.stopping_m),
                    reason=a.reason,
                    onboard_only=d.onboard_only,
                    **({} if f is None else {"onboard": f.short_name, "items": [f.first, f.last]}),
                )
            )
            events += self._act(s, level, onboard_only=d.onboard_only)
        events += self._traffic(s, float(x), float(y))
        calm = level == a.level == Level.CLEAR and not events
        self.reach = self._reach(s, x, y, speed, check) if calm and self.shortcut else None
        return events

    def set_fences(self, fences: FenceSet) -> None:
        """Check against ``fences`` from the next sample on (same frame: traffic stays put);
        the next position gets a full check, and the home's AMSL places their limits."""
        if self.fences.home_amsl is not None:
            fences.set_home(self.fences.home_amsl)
        self.fences = fences
        self.reach = None

    def _home(self, s):
        """Home's altitude AMSL (the sample's altitude AMSL less its height above home): the
        fences' AMSL limits follow it (:meth:`FenceSet.set_home`). Until one comes they hold
        at every altitude, said once (``altitude_unknown``)."""
        amsl, fs = s.alt_amsl_m, self.fences
        if isinstance(amsl, (int, float)) and math.isfinite(amsl):
            fs.set_home(amsl - s.alt_m)
        elif fs.home_amsl is None and not self.amsl_said:
            self.amsl_said = True
            if sites := fs.amsl_sites:
                why = f"no altitude AMSL: the AMSL limits of {len(sites)} fences hold at every altitude"
                return [new_event("altitude_unknown", s.t, s, fences=sites[:10], reason=why)]
        return []

    def load_onboard(self, items, t=None, union=False, **fields) -> list:
        """The vehicle's fence (its items, as downloaded) becomes the onboard layer, checked
        beside the full-resolution fences from the next step on, its inclusions read by the
        vehicle's rule (``union``: ``FENCE_OPTIONS`` bit 1); returns the events
        (``onboard_fence``, ``onboard_none``, ``onboard_failed``: see
        :func:`~alphafence.monitor.onboard.load_layer`)."""
        self.onboard, events = load_layer(
            self.onboard, items, self.fences, t, self.last, union, **fields
        )
        self.reach = None
        return events

    def onboard_unreadable(self, error, t=None, **fields) -> list:
        """The vehicle's fence could not be read: an ``onboard_failed`` event; the onboard
        layer in use (if any) is kept."""
        return unreadable(self.onboard, error, t, self.last, **fields)

    def aircraft(self, key, t, lat, lon, alt_amsl_m, ve, vn, vu=0.0, callsign=""):
        """Another aircraft's report (ADS-B or another MAVLink system) for the dynamic fences."""
        from alphafence.awareness.traffic import Aircraft

        x, y = self.fences.frame.to_local(lon, lat)
        self.reach = None
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
                    new_event(
                        "traffic_conflict",
                        s.t,
                        s,
                        aircraft=c.key,
                        callsign=c.callsign,
                        t_cpa_s=rounded(c.t_cpa_s),
                        separation_m=rounded(c.horizontal_m),
                        vertical_m=rounded(c.vertical_m),
                        radius_m=rounded(c.radius_m),
                    )
                )
        for key in self.conflicts - keys:
            events.append(new_event("traffic_clear", s.t, s, aircraft=key))
        self.conflicts = keys
        return events

    def tick_due(self) -> float:
        """When :meth:`tick` may next have something to say (monotonic seconds; infinity until
        telemetry has come, and once the link is lost): the runner sleeps until then instead
        of polling."""
        if self.last_t is None or self.link_lost:
            return math.inf
        return self.last_t + (self.options.link_lost_s if self.stale else self.options.stale_s)

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
        events = [new_event(kind, t, s, **extra)]
        if self.options.enforce and action != "none" and t >= self.backoff_until:
            events += self._command(t, s, action, reason=kind)
        return events

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
            events.append(new_event("reroute_cancelled", t, s, reason=f"action {action}"))
        if action != REROUTE:  # a re-route tells when it changes the mode (reroute_started)
            self._expect(t)
        return events + [new_event("action", t, s, action=action, **extra)]

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
            new_event("pilot_mode_change", s.t, s, mode=s.mode, backoff_s=self.options.backoff_s)
        ]
        if self.rerouting:  # the pilot flies now: the runner stops the re-route
            self.rerouting = False
            events.append(new_event("reroute_cancelled", s.t, s, reason="pilot changed mode"))
        return events

    def _act(self, s, level, onboard_only=False):
        o = self.options
        if level == Level.IMMINENT:
            action = o.imminent_action
            if onboard_only and action == REROUTE:  # the planner knows only the real fences
                action = REROUTE_FALLBACK
        elif level == Level.BREACH:
            action = o.breach_action
        else:
            return []
        if not o.enforce or action == "none":
            return []
        if s.t < self.backoff_until:
            return [
                new_event(
                    "action_withheld", s.t, s, action=action, reason="pilot changed mode recently"
                )
            ]
        if s.armed is False:
            return []
        if action == REROUTE and self.rerouting:
            return []  # one re-route at a time: the one under way already turns away
        return self._command(s.t, s, action)

    def _site(self, index):
        return None if index is None else self.fences.records[index].site_id
