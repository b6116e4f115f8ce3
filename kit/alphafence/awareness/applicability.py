"""ED-269 applicability: when a zone is in force (permanent, date ranges, weekly schedules)."""

from __future__ import annotations

from datetime import datetime, time, timezone

DAYS = ("MON", "TUE", "WED", "THU", "FRI", "SAT", "SUN")


def _dt(text):
    if not isinstance(text, str) or not text:
        return None
    try:
        value = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return None
    return value if value.tzinfo else value.replace(tzinfo=timezone.utc)


def _clock(text):
    if not isinstance(text, str):
        return None
    try:
        return time.fromisoformat(text.replace("Z", ""))
    except ValueError:
        return None


def _in_schedule(entry, when):
    days = entry.get("day") or []
    if isinstance(days, str):
        days = [days]
    if not isinstance(days, list):
        return True  # a schedule we cannot read is in force
    if days and "ANY" not in days and DAYS[when.weekday()] not in days:
        return False
    start, end = _clock(entry.get("startTime")), _clock(entry.get("endTime"))
    now = when.time().replace(tzinfo=None)
    if start and end:
        return start <= now <= end if start <= end else (now >= start or now <= end)
    return True


def is_active(applicability, when: datetime) -> bool:
    """Is a zone in force at ``when`` (aware datetime)? No or unreadable applicability: always
    (a restriction we cannot read is a restriction), whatever its shape.

    Examples
    --------
    >>> noon = datetime(2026, 12, 6, 12, 0, tzinfo=timezone.utc)
    >>> [is_active(a, noon) for a in (5, [{"schedule": 7}], [{"schedule": [{"day": 3}]}])]
    [True, True, True]
    """
    if not applicability:
        return True
    if isinstance(applicability, dict):
        applicability = [applicability]
    if not isinstance(applicability, list):
        return True  # a served value of another shape: unreadable, so in force
    for entry in applicability:
        if not isinstance(entry, dict):
            return True
        if str(entry.get("permanent", "")).upper() == "YES":
            return True
        start, end = _dt(entry.get("startDateTime")), _dt(entry.get("endDateTime"))
        if start and when < start or end and when > end:
            continue
        schedule = entry.get("schedule")
        if not schedule or not isinstance(schedule, list):
            return True
        if any(_in_schedule(s, when) for s in schedule if isinstance(s, dict)):
            return True
    return False


def timed(applicability) -> bool:
    """Does the zone switch on and off at all (else it is always in force)?"""
    if not applicability:
        return False
    entries = applicability if isinstance(applicability, list) else [applicability]
    return not any(
        isinstance(e, dict) and str(e.get("permanent", "")).upper() == "YES" for e in entries
    )


def active_within(applicability, when: datetime, slack_s: float = 0.0) -> bool:
    """Is a zone in force anywhere within ``when`` +- ``slack_s`` seconds (a clock that may be
    that far off)? The window's own starts and ends within that span are looked at too.

    Examples
    --------
    >>> w = [{"startDateTime": "2026-12-06T12:05:00Z", "endDateTime": "2026-12-06T13:00:00Z"}]
    >>> noon = datetime(2026, 12, 6, 12, 0, tzinfo=timezone.utc)
    >>> active_within(w, noon), active_within(w, noon, 600.0)
    (False, True)
    """
    from datetime import timedelta

    if is_active(applicability, when):
        return True
    if slack_s <= 0:
        return False
    lo, hi = when - timedelta(seconds=slack_s), when + timedelta(seconds=slack_s)
    probes = [lo, hi]
    entries = applicability if isinstance(applicability, list) else [applicability]
    for e in entries:
        for key in ("startDateTime", "endDateTime"):
            t = _dt(e.get(key)) if isinstance(e, dict) else None
            if t is not None and lo <= t <= hi:
                probes.append(t)
    return any(is_active(applicability, t) for t in probes)
