"""Recorded flights: a trace of what the monitor was fed, written, read back and replayed.

A trace is JSON lines: a header (``{"trace": ...}``: where it was recorded, at what SITL
speedup, the fence the vehicle held, as its items, and, when recorded, the clock: the UTC of
one monotonic time) and then one :class:`Sample` per line, as the monitor's engine stepped on
it. :func:`replay` feeds a trace to an :class:`Engine` of
its own, the vehicle's fence loaded as its onboard layer first, as the runner does at start.
A trace whose samples carry no ``alt_amsl_m`` (written before it was recorded) replays as it
did for fences without AMSL limits; AMSL limits then hold at every altitude, and an
``altitude_unknown`` event names the fences that have them.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field

from alphafence.awareness.fenceset import FenceSet
from alphafence.errors import InputError
from alphafence.mavlink.autopilots import ARDUPILOT, AUTOPILOTS
from alphafence.mavlink.items import FenceItem
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.events import WALL, UtcClock
from alphafence.monitor.observe import Observer, Step
from alphafence.monitor.options import MonitorOptions
from alphafence.vehicle.values import mode_name
from alphafence.zones.jsonfile import read_limited

TRACE_FORMAT = "alphafence-trace-1"
MAX_TRACE_BYTES = 20_000_000


@dataclass
class Trace:
    """A recorded flight.

    Attributes
    ----------
    recorded : str
        Where and how it was recorded (e.g. "ArduPilot SITL copter, speedup 5, ...").
    speedup : float
        The simulation's speedup: the samples' times are wall seconds, each ``speedup``
        seconds of flight.
    onboard_items : list of FenceItem
        The fence the vehicle held (as downloaded by the monitor at start).
    samples : list of Sample
        What the engine stepped on, in order.
    clock : dict, optional
        ``{"t": monotonic seconds, "utc": ISO 8601, "source": where UTC came from}``: the
        samples' times in UTC (None: the trace does not say).
    autopilot : str
        The vehicle's, which names its modes (``"ardupilot"``, ``"px4"``).
    """

    recorded: str
    speedup: float = 1.0
    onboard_items: list = field(default_factory=list)
    samples: list = field(default_factory=list)
    clock: dict | None = None
    autopilot: str = ARDUPILOT

    def utc_clock(self) -> UtcClock:
        """The :class:`UtcClock` of the samples' times: the trace's own (source ``trace``)
        or, without one, the wall clock from now on (the replay's first sample is now)."""
        if self.clock:
            source = f"trace ({self.clock.get('source') or 'recorded'})"
            return UtcClock.at(self.clock["t"], self.clock["utc"], source)
        t0 = self.samples[0].t if self.samples else 0.0
        return UtcClock.at(t0, time.time(), WALL)

    def to_text(self) -> str:
        """The trace as JSON lines (the header first)."""
        header = {
            "trace": TRACE_FORMAT,
            "recorded": self.recorded,
            "speedup": self.speedup,
            "onboard_items": [dataclasses.astuple(i) for i in self.onboard_items],
        }
        if self.clock:
            header["clock"] = self.clock
        if self.autopilot != ARDUPILOT:  # traces without it are ArduPilot's
            header["autopilot"] = self.autopilot
        lines = [json.dumps(header)]
        lines += [json.dumps(_rounded(dataclasses.asdict(s))) for s in self.samples]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_text(cls, text: str, source: str = "trace") -> Trace:
        """Read a trace written by :meth:`to_text`; InputError names ``source`` and the line."""
        lines = [line for line in text.splitlines() if line.strip()]
        if not lines:
            raise InputError(source, "empty trace")
        header = _line(lines[0], source, 1)
        if not isinstance(header, dict) or header.get("trace") != TRACE_FORMAT:
            raise InputError(source, f"line 1: not an AlphaFence trace ({TRACE_FORMAT})")
        autopilot = header.get("autopilot", ARDUPILOT)
        if autopilot not in AUTOPILOTS:
            raise InputError(source, f"line 1: autopilot {autopilot!r} is none of {AUTOPILOTS}")
        try:
            items = [
                FenceItem(int(c), float(p), float(x), float(y))
                for c, p, x, y in header.get("onboard_items", [])
            ]
            samples = [Sample(**_line(line, source, n)) for n, line in enumerate(lines[1:], 2)]
            for s in samples:  # a trace recorded through MAVSDK's link names modes its way
                s.mode = mode_name(s.mode, autopilot)
        except (TypeError, ValueError) as exc:
            raise InputError(source, f"malformed sample or item: {exc}") from None
        try:
            clock = header.get("clock")
            if clock is not None:
                UtcClock.at(float(clock["t"]), str(clock["utc"]), "trace")  # readable
        except (TypeError, ValueError, KeyError) as exc:
            raise InputError(source, f"line 1: malformed clock ({exc})") from None
        recorded = str(header.get("recorded", ""))
        speedup = float(header.get("speedup", 1.0))
        return cls(recorded, speedup, items, samples, clock, autopilot)

    @classmethod
    def read(cls, path) -> Trace:
        """Read a trace file (at most 20 MB)."""
        too_big = f"a trace over {MAX_TRACE_BYTES // 10**6} MB"
        data = read_limited(path, MAX_TRACE_BYTES, too_big)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(str(path), "not UTF-8") from None
        return cls.from_text(text, str(path))


def _rounded(sample: dict) -> dict:
    """A sample's floats to what telemetry resolves: 1e-8 degrees, 0.1 ms, 1 mm, 1 mm/s."""
    places = {"lat": 8, "lon": 8, "t": 4}
    return {k: round(v, places.get(k, 3)) if isinstance(v, float) else v for k, v in sample.items()}


def _line(line, source, n):
    try:
        return json.loads(line)
    except json.JSONDecodeError as exc:
        raise InputError(source, f"line {n}: not JSON ({exc.msg})") from None


class Recorder(Observer):
    """An observer that keeps every sample the engine stepped on (for a :class:`Trace`)."""

    def __init__(self):
        self.samples: list = []

    def on_step(self, step: Step) -> None:
        """Keep the step's sample."""
        self.samples.append(step.sample)


def replay(
    trace: Trace,
    fences: FenceSet,
    options: MonitorOptions | None = None,
    clock: UtcClock | None = None,
    **fields,
):
    """Feed a recorded flight to a fresh engine: the vehicle's fence first (as the onboard
    layer, when the options watch it and the trace holds one), then every sample.

    Parameters
    ----------
    trace : Trace
    fences : FenceSet
        The full-resolution fences.
    options : MonitorOptions, optional
        Durations are wall seconds (scale them for the trace's speedup, see
        :func:`speedup_options`).
    clock : UtcClock, optional
        The events' UTC (default :meth:`Trace.utc_clock`).
    **fields
        Added to every event (e.g. ``replay=True``).

    Returns
    -------
    list of dict
        Every event the engine decided, in order, its ``utc`` on ``clock``.
    """
    clock = clock or trace.utc_clock()
    engine = Engine(fences, options)
    events = []
    t0 = trace.samples[0].t if trace.samples else None
    if engine.options.onboard == "watch" and trace.onboard_items:
        events += engine.load_onboard(trace.onboard_items, t=t0, cause="start")
    for s in trace.samples:
        events += engine.step(s)
    return [{**clock.stamp(e), **fields} for e in events]


def speedup_options(speedup: float, **kw) -> MonitorOptions:
    """MonitorOptions for a simulation run ``speedup`` times faster than real time.

    The engine's own durations are wall seconds (telemetry arrival times) while speeds and
    the braking model are the vehicle's, so the wall-clock ones are scaled: unscaled, at
    speedup 5, 10 m/s is 50 m/s per wall second, within arrival jitter of the GPS-glitch
    speed, and the back-off after a pilot's mode change lasts 75 s of flight.
    """
    o = MonitorOptions(**kw)
    o.hold_s /= speedup
    o.backoff_s /= speedup
    o.stale_s /= speedup
    o.max_speed_mps *= speedup
    return o


HEARTBEAT_S = 1.0  # a telemetry log's HEARTBEATs: one a second, as ArduPilot sends them
BOOT_S = 60.0  # the vehicle's time since boot at the first sample (time_boot_ms)


def trace_tlog(trace: Trace, clock: UtcClock | None = None) -> bytes:
    """The recorded flight as a telemetry log (``.tlog``), as a ground station writes one:
    each MAVLink 2 frame after its timestamp (8 bytes, big-endian, UNIX microseconds).

    Every sample becomes a GLOBAL_POSITION_INT (position, altitudes, velocity), with a
    HEARTBEAT (an ArduPilot copter, its mode's ``custom_mode``, armed or not) before the first,
    then once a second and whenever the mode or the armed state changes, so that ``alphafence check-flight`` and log viewers read it.

    Parameters
    ----------
    trace : Trace
    clock : UtcClock, optional
        The samples' times in UTC (default :meth:`Trace.utc_clock`): the same as the events
        of a replay on it, so the log and the events line up.

    Returns
    -------
    bytes
    """
    import struct

    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from alphafence.geo.coords import to_e7
    from alphafence.mavlink import ids
    from alphafence.vehicle.values import custom_mode_of

    clock = clock or trace.utc_clock()
    frames = _Frames()
    mav = mavlink.MAVLink(frames, srcSystem=1, srcComponent=1)
    t0 = trace.samples[0].t if trace.samples else 0.0
    beat, state = -math.inf, None
    for s in trace.samples:
        frames.stamp = struct.pack(">Q", round((s.t + clock.offset_s) * 1e6))
        armed = ids.MAV_MODE_FLAG_SAFETY_ARMED if s.armed else 0
        mode = custom_mode_of(s.mode) or 0
        if s.t - beat >= HEARTBEAT_S or (mode, armed) != state:
            beat, state = s.t, (mode, armed)
            mav.heartbeat_send(
                ids.MAV_TYPE_QUADROTOR,
                ids.MAV_AUTOPILOT_ARDUPILOTMEGA,
                ids.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | armed,
                mode,
                ids.MAV_STATE_ACTIVE,
            )
        amsl = s.alt_amsl_m if s.alt_amsl_m is not None else s.alt_m
        mav.global_position_int_send(
            round((s.t - t0 + BOOT_S) * 1000),
            to_e7(s.lat),
            to_e7(s.lon),
            round(amsl * 1000),
            round(s.alt_m * 1000),
            round(s.vn * 100),
            round(s.ve * 100),
            round(s.vd * 100),
            UINT16_MAX,  # heading unknown
        )
    return bytes(frames.data)


UINT16_MAX = 65535  # GLOBAL_POSITION_INT's hdg when it is not known


class _Frames:
    """A file for pymavlink's encoder: each frame written after the current timestamp."""

    def __init__(self):
        self.data = bytearray()
        self.stamp = b""

    def write(self, frame: bytes) -> None:
        self.data += self.stamp + frame
