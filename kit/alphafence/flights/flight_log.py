"""Flight logs read as a track: telemetry logs (``.tlog``), ArduPilot DataFlash logs (``.BIN``),
PX4's ULog (``.ulg``, :mod:`alphafence.flights.ulog`).

A track comes in chunks of arrays (:class:`TrackChunk`: time, latitude, longitude, height above
home, altitude AMSL, velocity), so a log of any length is read in bounded memory.

* A ``.tlog`` (MAVProxy, QGroundControl, Mission Planner) is MAVLink packets, each after the
  8-byte big-endian microseconds (UNIX time) at which the ground station received it; it is read
  with pymavlink's log reader. Positions are the vehicle's ``GLOBAL_POSITION_INT`` (1e-7 degrees,
  ``alt`` AMSL and ``relative_alt`` above home in millimetres, ``vx``/``vy`` in cm/s), timed by
  the log's own timestamps.
* A DataFlash ``.BIN`` (the autopilot's own log) is self-describing messages (``0xA3 0x95``,
  a type, fields as its ``FMT`` message says). Positions are ``POS`` (the AHRS's position:
  ``Alt`` AMSL, ``RelHomeAlt`` above home), or ``GPS`` instance 0 when the log has no ``POS``.
  ``TimeUS`` is time since boot; the GPS week and milliseconds (``GWk``, ``GMS``) of the first
  GPS message that has them give the UTC time of boot (GPS time less its leap seconds). Logs
  written before 2015 have no ``TimeUS`` and no ``POS``: their ``GPS`` messages
  (``Status,TimeMS,Week,...,T``) give the GPS time in ``Week`` and ``TimeMS`` and the
  milliseconds since boot in ``T`` (a ``GPS`` without ``T`` is timed by its own GPS time; one
  with ``GWk``/``GMS`` beside ``TimeMS`` by ``TimeMS`` since boot). It is streamed with
  pymavlink's DataFlash field types, decoding only the messages it needs (checked against
  pymavlink's own ``DFReader`` by ``tests/test_check_flight.py``).

A log that ends within a message (logging stopped mid-write) is read up to there and says so
(:attr:`LogInfo.truncated`); a file that holds no position at all is an :class:`InputError`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from alphafence.errors import InputError, need
from alphafence.flights import dataflash, ulog

CHUNK = 2048  # positions per chunk
PLAUSIBLE_UNIX = 946684800  # 2000-01-01: an earlier tlog timestamp is not a wall clock
LATEST_UNIX = 4102444800  # 2100-01-01: a later time is a corrupt one


@dataclass
class TrackChunk:
    """Consecutive positions of a flight, as arrays of equal length.

    Attributes
    ----------
    t : numpy.ndarray
        Seconds: UNIX time when the log's clock is ``"utc"``, else seconds since boot.
    lat, lon : numpy.ndarray
        Degrees.
    alt_rel : numpy.ndarray
        Metres above home (NaN when the log does not say).
    alt_amsl : numpy.ndarray
        Metres above mean sea level.
    vn, ve : numpy.ndarray
        Metres per second north and east (NaN when the log does not say).
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt_rel: np.ndarray
    alt_amsl: np.ndarray
    vn: np.ndarray
    ve: np.ndarray

    def __len__(self):
        return len(self.t)


@dataclass
class LogInfo:
    """What a log is and what reading it found (filled in as its chunks are read).

    Attributes
    ----------
    path : str
    kind : str
        ``"tlog"``, ``"dataflash"`` or ``"ulog"``.
    source : str
        The message the positions come from (``GLOBAL_POSITION_INT``, ``POS``, ``GPS``).
    clock : str
        ``"utc"`` (times are UNIX seconds) or ``"boot"`` (seconds since boot: no wall clock).
    sysid : int or None
        The MAVLink system whose positions were read (a tlog).
    messages, positions, skipped : int
        Messages read, positions kept, positions dropped (no fix, repeated, out of order).
    bad_bytes : int
        Corrupt bytes skipped.
    truncated : bool
        The log ends within a message.
    notes : list of str
        What the reader had to assume or leave out, one sentence each.
    """

    path: str
    kind: str
    source: str = ""
    clock: str = "utc"
    sysid: int | None = None
    messages: int = 0
    positions: int = 0
    skipped: int = 0
    bad_bytes: int = 0
    truncated: bool = False
    notes: list = field(default_factory=list)


def usable(t, lat, lon, rel, amsl) -> bool:
    """Is this a position to check: finite, on the globe, not 0,0 (a GPS without a fix yet),
    at a time from 1970 to 2100?

    Examples
    --------
    >>> usable(1.7e9, 35.9, 14.5, 50.0, 150.0), usable(1.7e9, 0.0, 0.0, 0.0, 0.0)
    (True, False)
    """
    values = (t, lat, lon, rel, amsl)
    if not all(isinstance(v, (int, float)) and np.isfinite(v) for v in values):
        return False
    return 0 <= t < LATEST_UNIX and abs(lat) <= 90 and abs(lon) <= 180 and (lat, lon) != (0, 0)


class _Chunks:
    """Positions gathered into :class:`TrackChunk` arrays of ``size`` rows."""

    def __init__(self, size):
        self.size = size
        self.rows = []

    def add(self, *row):
        self.rows.append(row)
        return len(self.rows) >= self.size

    def take(self):
        a = np.array(self.rows, dtype=float).reshape(-1, 7)
        self.rows = []
        return TrackChunk(*(a[:, k].copy() for k in range(7)))


def log_kind(path) -> str:
    """``"dataflash"``, ``"ulog"`` or ``"tlog"``, told by the first bytes (a DataFlash log
    starts with a message header, a ULog with its magic), whatever the suffix; InputError for a
    missing file, a text DataFlash log or a ``.bin`` that is not one."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror or exc})") from None
    if not head:
        raise InputError(path, "empty file: not a flight log")
    if head[:2] == dataflash.HEAD:
        return "dataflash"
    if ulog.is_ulog(head):
        return "ulog"
    if head.startswith(b"FMT,"):
        raise InputError(path, "a text DataFlash log: give the binary log (.BIN) instead")
    if Path(path).suffix.lower() == ".bin":
        raise InputError(path, "not a DataFlash log: it does not start with a message header")
    return "tlog"


def log_reader(path) -> str:
    """The package that reads the log: ``"pyulog"`` for a ULog, else (a bad file too)
    ``"pymavlink"``."""
    try:
        return "pyulog" if log_kind(path) == "ulog" else "pymavlink"
    except InputError:  # the reader says what is wrong with it
        return "pymavlink"


class FlightLog:
    """A flight log, read on demand as :class:`TrackChunk` arrays.

    Parameters
    ----------
    path : str or Path
        A ``.tlog``, a DataFlash ``.BIN`` or a ULog ``.ulg`` (told by its first bytes).
    sysid : int, optional
        A tlog's vehicle (MAVLink system id); default the first system reporting a position.
    chunk : int
        Positions per chunk.

    Raises
    ------
    InputError
        The file is missing, empty or not a flight log.
    MissingDependency
        pymavlink is not installed.
    """

    def __init__(self, path, sysid: int | None = None, chunk: int = CHUNK):
        self.path = str(path)
        kind = log_kind(path)
        need((log_reader(path), f"reading {self.path}"))
        self.sysid = sysid
        self.chunk = chunk
        self.info = LogInfo(self.path, kind)

    def chunks(self):
        """The track, chunk by chunk (read afresh on every call).

        Yields
        ------
        TrackChunk

        Raises
        ------
        InputError
            When the log holds no position (after the last chunk, if any came).
        """
        self.info = LogInfo(self.path, self.info.kind)
        if self.info.kind == "ulog":
            yield from (TrackChunk(*c) for c in ulog.read_ulog(self.path, self.info, self.chunk))
        else:
            reader = _tlog if self.info.kind == "tlog" else _dataflash
            yield from reader(self.path, self.info, self.sysid, self.chunk)
        if self.info.truncated:
            self.info.notes.append("the log ends within a message: read up to there")


# -- tlog ---------------------------------------------------------------------------------
def _tlog(path, info, sysid, size):
    from pymavlink import mavutil

    info.source = "GLOBAL_POSITION_INT"
    out = _Chunks(size)
    others, last_ms, last_t, end = set(), None, -np.inf, 0
    conn = mavutil.mavlogfile(path, robust_parsing=True)
    try:
        while True:
            try:
                m = conn.recv_msg()
            except Exception as exc:  # pymavlink's parser on a hostile byte sequence
                raise InputError(path, f"unreadable MAVLink data ({exc})") from None
            if m is None:
                break
            kind = m.get_type()
            if kind == "BAD_DATA":
                info.bad_bytes += len(getattr(m, "data", b"") or b"")
                continue
            if kind.startswith("UNKNOWN"):  # a frame of an unknown id: likely noise
                continue
            info.messages += 1
            end = conn.f.tell() - conn.mav.buf_len()  # where the last whole message ends
            if kind != "GLOBAL_POSITION_INT":
                continue
            src = m.get_srcSystem()
            if sysid is None:
                sysid = info.sysid = src
            if src != sysid:
                others.add(src)
                continue
            t = float(m._timestamp)
            row = (t, m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3, m.alt * 1e-3)
            if m.time_boot_ms == last_ms or not usable(*row) or t < last_t:
                info.skipped += 1  # a repeat (two links), no fix yet, out of order
                continue
            last_ms, last_t = m.time_boot_ms, t
            if info.positions == 0 and t < PLAUSIBLE_UNIX:
                info.clock = "boot"
                info.notes.append("the log's timestamps are not wall-clock times")
            info.positions += 1
            if out.add(*row, m.vx * 1e-2, m.vy * 1e-2):
                yield out.take()
        info.truncated = info.messages > 0 and os.path.getsize(path) > end
    finally:
        conn.close()
    if out.rows:
        yield out.take()
    info.sysid = sysid
    if others:
        ids = ", ".join(map(str, sorted(others)))
        info.notes.append(f"positions of other systems ({ids}) were not checked (--sysid)")
    if info.messages == 0:
        raise InputError(path, "no MAVLink messages in it: not a telemetry log")
    if info.positions == 0:
        why = f" of system {sysid}" if sysid is not None else ""
        raise InputError(path, f"no GLOBAL_POSITION_INT with a position{why}: nothing to check")


# -- DataFlash ----------------------------------------------------------------------------
def _number(fmt, v, column, default=None):
    """A numeric field, or ``default`` when the type has no such column; ValueError when the
    field is not a number (a corrupt or foreign FMT)."""
    if column not in fmt.columns:
        return default
    if not isinstance(v[fmt.columns[column][0]], (int, float)):
        raise ValueError(column)
    return dataflash.value(fmt, v, column)


def _gps_week_ms(fmt, v):
    """A GPS message's GPS week and milliseconds into it (``GWk``, ``GMS``; before 2015
    ``Week``, ``TimeMS``), ``(None, None)`` when it has none or the GPS had no time yet."""
    week, ms = ("GWk", "GMS") if "GWk" in fmt.columns else ("Week", "TimeMS")
    week, ms = _number(fmt, v, week), _number(fmt, v, ms)
    return (week, ms) if week is not None and ms is not None and week > 0 else (None, None)


def _boot_seconds(fmt, v):
    """Seconds since boot of a POS or GPS message: ``TimeUS``; before 2015 ``T`` (milliseconds)
    of a GPS message whose ``TimeMS`` is GPS time (it has ``Week``), else ``TimeMS``; None when
    the message has no such field."""
    us = _number(fmt, v, "TimeUS")
    if us is not None:
        return us * 1e-6
    ms = _number(fmt, v, "T" if "Week" in fmt.columns else "TimeMS")
    return None if ms is None else ms * 1e-3


def _dataflash_survey(path):
    """A first pass: the UTC time of boot (from GPS time; 0.0 when the GPS messages have no
    time since boot and are timed by their own GPS time), whether the log has POS, and home's
    altitude (ORGN type 1) for logs without a height above home."""
    boot_utc = home = None
    has_pos = False
    for fmt, v in dataflash.messages(path, LogInfo(path, "dataflash"), ("GPS", "POS", "ORGN")):
        try:
            if fmt.name == "POS":
                has_pos = has_pos or bool(_number(fmt, v, "Lat", 0) or _number(fmt, v, "Lng", 0))
            elif fmt.name == "GPS" and boot_utc is None and _number(fmt, v, "I", 0) == 0:
                (week, ms), boot = _gps_week_ms(fmt, v), _boot_seconds(fmt, v)
                if week is not None:
                    boot_utc = 0.0 if boot is None else dataflash.gps_utc(week, ms) - boot
            elif fmt.name == "ORGN" and home is None and _number(fmt, v, "Type") == 1:
                home = _number(fmt, v, "Alt")
        except (ValueError, OverflowError):
            continue
        if boot_utc is not None and has_pos and home is not None:
            break
    return boot_utc, has_pos, home


def _dataflash_position(fmt, v, boot_utc):
    """``(t, lat, lon, height above home or None, AMSL, vn, ve)`` of a POS or GPS message, or
    None for one without a position (another GPS instance, no 3D fix, no time)."""
    if _number(fmt, v, "I", 0) != 0 or _number(fmt, v, "Status", 3) < 3:
        return None
    lat, lon, amsl = (_number(fmt, v, k) for k in ("Lat", "Lng", "Alt"))
    t = _boot_seconds(fmt, v)
    if t is not None:
        t += boot_utc or 0.0
    elif fmt.name == "GPS" and _gps_week_ms(fmt, v)[0] is not None:
        t = dataflash.gps_utc(*_gps_week_ms(fmt, v))  # a GPS message timed by GPS time alone
    if None in (t, lat, lon, amsl):
        return None
    rel = _number(fmt, v, "RelHomeAlt", _number(fmt, v, "RelAlt"))
    vn = ve = float("nan")
    spd, crs = _number(fmt, v, "Spd"), _number(fmt, v, "GCrs")
    if spd is not None and crs is not None:
        vn, ve = spd * math.cos(math.radians(crs)), spd * math.sin(math.radians(crs))
    return t, lat, lon, rel, amsl, vn, ve


def _dataflash(path, info, sysid, size):
    boot_utc, has_pos, home = _dataflash_survey(path)
    info.source = "POS" if has_pos else "GPS"
    if boot_utc is None:
        info.clock = "boot"
        info.notes.append("no GPS time in the log: times are seconds since boot")
    out = _Chunks(size)
    last_t = -np.inf
    for fmt, v in dataflash.messages(path, info, (info.source,)):
        try:
            p = _dataflash_position(fmt, v, boot_utc)
        except (ValueError, OverflowError):
            p = None
            info.skipped += 1
        if p is None:
            continue
        t, lat, lon, rel, amsl, vn, ve = p
        if rel is None:  # an old log: no height above home
            if home is None and usable(t, lat, lon, 0.0, amsl):
                home = amsl  # the first fix: the vehicle on the ground before take-off
                info.notes.append(
                    "no height above home in the log: home taken as the first fix's altitude"
                )
            rel = amsl - (home if home is not None else amsl)
        if not usable(t, lat, lon, rel, amsl) or t <= last_t:
            info.skipped += 1
            continue
        last_t = t
        info.positions += 1
        if out.add(t, lat, lon, rel, amsl, vn, ve):
            yield out.take()
    if out.rows:
        yield out.take()
    if info.messages == 0:
        raise InputError(path, "no DataFlash messages in it: not a DataFlash log")
    if info.positions == 0:
        raise InputError(path, "no POS or GPS message with a position: nothing to check")
