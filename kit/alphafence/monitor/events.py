"""The monitor's events, built one way, and what each one says to the ground station.

An event is a plain dict (it is written to the event log as one JSON line, echoed by the CLI
and kept in memory): ``time`` (monotonic seconds, rounded to the millisecond), ``event`` (its
kind), then, when it happened at a position, ``lat``, ``lon`` and ``alt_m``, then its own
fields. :func:`new_event` builds every one of them, the engine's and the runner's alike.
"""

from __future__ import annotations

import math
import time


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
        ``{"time", "event", ["lat", "lon", "alt_m",] **fields}``.

    Examples
    --------
    >>> new_event("action_done", 12.34567, action="brake")
    {'time': 12.346, 'event': 'action_done', 'action': 'brake'}
    """
    event = {"time": round(time.monotonic() if t is None else t, 3), "event": kind}
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
    return None
