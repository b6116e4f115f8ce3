"""PX4's flight logs (ULog, ``.ulg``) read as a track, with pyulog.

A ULog starts with ``ULog`` and the bytes ``01 12 35``; its messages are uORB topics, each
sample stamped with microseconds since boot. The track is ``vehicle_global_position`` (the
estimator's position: ``lat``, ``lon`` in degrees, ``alt`` AMSL), where ``lat_lon_valid``:

- height above home: ``alt`` less the altitude of the ``home_position`` in force at that time
  (NaN before PX4 set home);
- velocity: ``vehicle_local_position``'s ``vx`` (north) and ``vy`` (east) at the same time,
  interpolated between its samples (NaN outside them);
- clock: UTC when a GPS sample (``vehicle_gps_position``) gives ``time_utc_usec``: the
  offset between it and the sample's own timestamp times every position; else seconds since
  boot (PX4 SITL's simulated GPS gives no UTC).

pyulog reads the topics asked for at once (the rest of the file is skipped), so a log's
memory is its positions; a file pyulog cannot read is an :class:`InputError` naming it.
"""

from __future__ import annotations

import numpy as np

from alphafence.errors import InputError

MAGIC = b"ULog\x01\x12\x35"
POSITION = "vehicle_global_position"
TOPICS = (POSITION, "vehicle_local_position", "home_position", "vehicle_gps_position")


def is_ulog(head: bytes) -> bool:
    """Whether a file's first bytes are a ULog's.

    Examples
    --------
    >>> is_ulog(b"ULog\\x01\\x12\\x35\\x01"), is_ulog(b"\\xa3\\x95\\x80")
    (True, False)
    """
    return head[: len(MAGIC)] == MAGIC


def _topics(path) -> dict:
    from pyulog import ULog

    try:
        log = ULog(str(path), list(TOPICS))
    except Exception as exc:  # pyulog raises its own and struct's errors on a broken file
        raise InputError(path, f"not a readable ULog ({exc})") from None
    out = {}
    for d in log.data_list:  # the first instance of each topic
        out.setdefault(d.name, d.data)
    return out


def _utc_offset(gps) -> float | None:
    """Seconds to add to a boot time for UTC, from the first GPS sample that gives UTC."""
    if gps is None or "time_utc_usec" not in gps:
        return None
    utc = np.asarray(gps["time_utc_usec"], dtype=np.int64)
    at = np.flatnonzero(utc > 0)
    if not at.size:
        return None
    k = at[0]
    return (int(utc[k]) - int(gps["timestamp"][k])) / 1e6


def _home_alt(home, t_us) -> np.ndarray:
    """The altitude of the home in force at each time (NaN before the first)."""
    out = np.full(t_us.shape, np.nan)
    if home is None or not len(home["timestamp"]):
        return out
    k = np.searchsorted(np.asarray(home["timestamp"]), t_us, side="right") - 1
    ok = k >= 0
    out[ok] = np.asarray(home["alt"], float)[k[ok]]
    return out


def _velocity(local, t_us) -> tuple:
    nan = np.full(t_us.shape, np.nan)
    if local is None or not len(local["timestamp"]):
        return nan, nan.copy()
    lt = np.asarray(local["timestamp"], float)
    vn = np.interp(t_us, lt, np.asarray(local["vx"], float), left=np.nan, right=np.nan)
    ve = np.interp(t_us, lt, np.asarray(local["vy"], float), left=np.nan, right=np.nan)
    return vn, ve


def read_ulog(path, info, size):
    """The track of a ULog in chunks of ``size`` rows, filling ``info``: each chunk the
    columns of a :class:`~alphafence.flights.flight_log.TrackChunk` (time, lat, lon, height
    above home, AMSL, velocity north and east).

    Raises
    ------
    InputError
        pyulog cannot read it, or it holds no valid position.
    """
    topics = _topics(path)
    info.source = POSITION
    pos = topics.get(POSITION)
    if pos is None or not len(pos["timestamp"]):
        raise InputError(path, f"no {POSITION} in the log: nothing to check")
    t_us = np.asarray(pos["timestamp"], np.int64)
    lat, lon = np.asarray(pos["lat"], float), np.asarray(pos["lon"], float)
    amsl = np.asarray(pos["alt"], float)
    info.messages = len(t_us)
    offset = _utc_offset(topics.get("vehicle_gps_position"))
    if offset is None:
        info.clock = "boot"
        info.notes.append("no GPS time in the log: times are seconds since boot")
    t = t_us / 1e6 + (offset or 0.0)
    rel = amsl - _home_alt(topics.get("home_position"), t_us)
    vn, ve = _velocity(topics.get("vehicle_local_position"), t_us)
    valid = np.asarray(pos.get("lat_lon_valid", np.ones(len(t_us))), bool)
    ok = valid & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(amsl) & ((lat != 0) | (lon != 0))
    ok &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    # in order: a time not after the last kept one is dropped, as the other readers do
    ok &= np.concatenate([[True], t[1:] > np.maximum.accumulate(t)[:-1]])
    if np.isnan(rel[ok]).any():
        info.notes.append("positions before PX4 set home have no height above home")
    info.skipped = int((~ok).sum())
    info.positions = int(ok.sum())
    if not info.positions:
        raise InputError(path, f"no valid position in {POSITION}: nothing to check")
    cols = [a[ok] for a in (t, lat, lon, rel, amsl, vn, ve)]
    for a in range(0, info.positions, size):
        yield [c[a : a + size].copy() for c in cols]
