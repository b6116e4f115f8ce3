"""The monitor's events, built one way, and what each one says to the ground station.

An event is a plain dict (it is written to the event log as one JSON line, echoed by the CLI
and kept in memory): ``time`` (monotonic seconds, rounded to the millisecond), ``utc`` (the
same moment in UTC, ISO 8601 to the millisecond, e.g. ``2026-12-02T07:30:01.234Z``, to line
up with flight logs), ``event`` (its kind), then, when it happened at a position, ``lat``,
``lon`` and ``alt_m``, then its own fields. :func:`new_event` builds every one of them, the
engine's and the runner's alike, with UTC from this computer's clock; a replay stamps them
again with the :class:`UtcClock` of the flight it replays, and the event log's first line
(a ``clock`` event) says where its UTC comes from.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from datetime import datetime, timezone

WALL = "wall clock"
"""A :class:`UtcClock` source: this computer's clock (NTP-set on most)."""


def utc_text(epoch_s: float) -> str:
    """UNIX seconds as ISO 8601 UTC to the millisecond, ``Z`` for UTC.

    Examples
    --------
    >>> utc_text(1796196601.2345)
    '2026-12-02T07:30:01.234Z'
    """
    when = datetime.fromtimestamp(epoch_s, timezone.utc)
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def utc_seconds(text: str) -> float:
    """ISO 8601 UTC text (as :func:`utc_text` writes it) as UNIX seconds.

    Examples
    --------
    >>> utc_seconds("2026-12-02T07:30:01.234Z")
    1796196601.234
    """
    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


@dataclass(frozen=True)
class UtcClock:
    """Monotonic seconds (events' ``time``) to UTC: ``utc = t + offset_s``.

    Attributes
    ----------
    offset_s : float
        UNIX seconds at monotonic time 0.
    source : str
        Where UTC comes from: :data:`WALL`, ``"trace"`` (the clock a replayed flight
        recorded), ``"vehicle SYSTEM_TIME"``.

    Examples
    --------
    >>> clock = UtcClock.at(100.0, "2026-12-02T07:30:00Z", "trace")
    >>> clock.utc(101.234), clock.source
    ('2026-12-02T07:30:01.234Z', 'trace')
    """

    offset_s: float
    source: str = WALL

    @classmethod
    def wall(cls) -> UtcClock:
        """This computer's clock, for events timed by its ``time.monotonic()``."""
        return cls(time.time() - time.monotonic(), WALL)

    @classmethod
    def at(cls, t: float, utc, source: str) -> UtcClock:
        """The clock on which monotonic ``t`` is ``utc`` (ISO text or UNIX seconds)."""
        epoch = utc_seconds(utc) if isinstance(utc, str) else float(utc)
        return cls(epoch - t, source)

    def utc(self, t: float) -> str:
        """Monotonic ``t`` in UTC (:func:`utc_text`)."""
        return utc_text(t + self.offset_s)

    def stamp(self, event: dict) -> dict:
        """``event`` with its ``utc`` from this clock (placed after ``time``)."""
        head = {"time": event["time"], "utc": self.utc(event["time"])}
        return {**head, **{k: v for k, v in event.items() if k not in head}}

    def event(self, t: float | None = None, **fields) -> dict:
        """The ``clock`` event an event log starts with: where its UTC comes from
        (``utc_source``), with ``fields``."""
        return self.stamp(new_event("clock", t, None, utc_source=self.source, **fields))


def rounded(value, digits: int = 2):
    """``value`` rounded for the log; None for what is missing or not finite (the log is
    strict JSON).

    Examples
    --------
    >>> rounded(1.23456), rounded(float("nan")), rounded(None), rounded("x")
    (1.23, None, None, None)
    """
    try:
        return None if value is None or not math.isfinite(value) else round(float(value), digits)
    except TypeError:
        return None


def new_event(kind: str, t: float | None = None, at=None, /, **fields) -> dict:
    """One event, as the log writes it.

    Parameters
    ----------
    kind : str
        What happened (``"level"``, ``"action"``, ``"adsb_unavailable"``, ...).
    t : float, optional
        When, in ``time.monotonic()`` seconds; now if omitted.
    at : Sample, optional
        Where the vehicle was: adds ``lat``, ``lon`` (7 decimals) and ``alt_m`` (2).
    **fields
        The event's own fields, in the order given.

    Returns
    -------
    dict
        ``{"time", "utc", "event", ["lat", "lon", "alt_m",] **fields}``; ``utc`` is ``t``
        on this computer's clock (a replay stamps its own, :meth:`UtcClock.stamp`).

    Examples
    --------
    >>> e = new_event("action_done", 12.34567, action="brake")
    >>> list(e), e["time"], e["utc"].endswith("Z")
    (['time', 'utc', 'event', 'action'], 12.346, True)
    """
    t = time.monotonic() if t is None else t
    offset = time.time() - time.monotonic()
    event = {"time": round(t, 3), "utc": utc_text(t + offset), "event": kind}
    if at is not None:
        event.update(lat=rounded(at.lat, 7), lon=rounded(at.lon, 7), alt_m=rounded(at.alt_m))
    event.update(fields)
    return event


def alert_text(event) -> str | None:
    """A STATUSTEXT (<= 50 characters) for the ground station, or None.

    Parameters
    ----------
    event : dict
        An event from :func:`new_event`.

    Returns
    -------
    str or None
        The alert text, or None for an event the ground station is not told about.

    Examples
    --------
    >>> alert_text({"event": "level", "level": "BREACH", "fence": "prison/way/1"})
    'AF BREACH prison/way/1'
    >>> alert_text({"event": "level", "level": "IMMINENT", "time_to_breach_s": 3.2,
    ...             "onboard_only": True, "onboard": "excl circle 5 #46"})
    'AF IMMINENT ONBOARD ONLY excl circle 5 #46 3s'
    >>> alert_text({"event": "onboard_upload_failed", "stage": "upload"})
    'AF onboard upload failed: old fence kept'
    """
    kind = event["event"]
    if kind == "level":
        text = f"AF {event['level']} {event.get('fence') or ''}"
        if event.get("onboard_only"):  # only the vehicle's own fence: its item, in short
            text = f"AF {event['level']} ONBOARD ONLY {event.get('onboard') or ''}"
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
    if kind == "onboard_failed":
        return "AF onboard fence unreadable"
    if kind == "onboard_none":
        return "AF no onboard fence"
    if kind == "onboard_upload_failed":
        return f"AF onboard {event.get('stage', 'upload')} failed: old fence kept"[:50]
    if kind == "onboard_behind":
        return "AF onboard fence behind the vehicle's reach"
    return _source_text(event)


def _source_text(event) -> str | None:
    """The alerts of a live source's events: zones new, lifted, opening and closing; the
    source stale, empty, or its clock off.

    Examples
    --------
    >>> _source_text({"event": "source_zone", "change": "new", "name": "police closure",
    ...               "window": "active"})
    'AF NEW ZONE police closure'
    >>> _source_text({"event": "source_zone_window", "name": "fire", "window": "upcoming"})
    'AF ZONE SOON fire'
    >>> _source_text({"event": "source_stale", "seconds": 95.2})
    'AF zone source stale 95s: zones kept'
    >>> _source_text({"event": "source_zone_removed", "name": "fire\\nPOWER OFF"})
    'AF zone lifted fire POWER OFF'
    """
    kind, name = event["event"], str(event.get("name") or event.get("zone") or "")
    name = "".join(c if c.isprintable() else " " for c in name[:50])  # a server's text
    if kind == "source_zone":
        what = {"active": "NEW ZONE", "always": "NEW ZONE", "upcoming": "ZONE SOON"}.get(
            event.get("window"), "zone"
        )
        if event.get("change") == "changed":
            what = "ZONE CHANGED"
        return f"AF {what} {name}"[:50] if what != "zone" else None
    if kind == "source_zone_window":
        what = {"active": "ZONE NOW", "upcoming": "ZONE SOON", "ended": "zone ended"}
        return f"AF {what[event['window']]} {name}"[:50] if event["window"] in what else None
    if kind == "source_zone_removed":
        return f"AF zone lifted {name}"[:50]
    if kind == "source_stale":
        return f"AF zone source stale {event.get('seconds', 0):.0f}s: zones kept"[:50]
    if kind == "source_empty":
        return "AF zone source empty: zones kept"
    if kind == "source_clock":
        if event.get("refused"):
            return "AF zone source clock refused: over 24 h off"
        return f"AF clock off {event.get('skew_s', 0):+.0f}s: windows widened"[:50]
    if kind == "source_ended":
        return "AF ZONE SOURCE ENDED: zones kept, none new"
    if kind == "source_fresh":
        return "AF zone source back"
    return None
