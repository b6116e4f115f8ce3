"""Flight logs read as a track: telemetry logs (``.tlog``) and ArduPilot DataFlash logs (``.BIN``).

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
  GPS message that has them give the UTC time of boot (GPS time less its leap seconds). It is
  streamed with pymavlink's table of DataFlash field types (``DFReader.FORMAT_TO_STRUCT``),
  decoding only the messages it needs; ``tests/test_check_flight.py`` checks it against
  pymavlink's own ``DFReader``.

A log that ends within a message (logging stopped mid-write) is read up to there and says so
(:attr:`LogInfo.truncated`); a file that holds no position at all is an :class:`InputError`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from alphafence.errors import InputError, need
from alphafence.formats import dataflash

CHUNK = 2048  # positions per chunk
PLAUSIBLE_UNIX = 946684800  # 2000-01-01: an earlier tlog timestamp is not a wall clock


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
        ``"tlog"`` or ``"dataflash"``.
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
    """``"dataflash"`` or ``"tlog"``, told by the first bytes (a DataFlash log starts with a
    message header), whatever the suffix; InputError for a missing file, a text DataFlash log
    or a ``.bin`` that is not one."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror or exc})") from None
    if not head:
        raise InputError(path, "empty file: not a flight log")
    if head[:2] == dataflash.HEAD:
        return "dataflash"
    if head.startswith(b"FMT,"):
        raise InputError(path, "a text DataFlash log: give the binary log (.BIN) instead")
    if Path(path).suffix.lower() == ".bin":
        raise InputError(path, "not a DataFlash log: it does not start with a message header")
    return "tlog"


class FlightLog:
    """A flight log, read on demand as :class:`TrackChunk` arrays.

    Parameters
    ----------
    path : str or Path
        A ``.tlog`` or a DataFlash ``.BIN`` (told by its first bytes).
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

    Examples
    --------
    >>> log = FlightLog("flight.tlog")  # doctest: +SKIP
    >>> sum(len(c) for c in log.chunks()), log.info.clock  # doctest: +SKIP
    (1800, 'utc')
    """

    def __init__(self, path, sysid: int | None = None, chunk: int = CHUNK):
        self.path = str(path)
        kind = log_kind(path)
        need(("pymavlink", f"reading {self.path}"))
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
            if m.time_boot_ms == last_ms or (m.lat == 0 and m.lon == 0) or t < last_t:
                info.skipped += 1  # a repeat (two links), no fix yet, or out of order
                continue
            last_ms, last_t = m.time_boot_ms, t
            if info.positions == 0 and t < PLAUSIBLE_UNIX:
                info.clock = "boot"
                info.notes.append("the log's timestamps are not wall-clock times")
            info.positions += 1
            row = (t, m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3, m.alt * 1e-3)
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
def _dataflash_survey(path, info):
    """A first pass: the UTC time of boot (from GPS time), whether the log has POS, and
    home's altitude (ORGN type 1) for logs without a height above home."""
    boot_utc = has_pos = home = None
    for fmt, v in dataflash.messages(path, LogInfo(path, "dataflash"), ("GPS", "POS", "ORGN")):
        c = fmt.columns
        if fmt.name == "POS" and {"TimeUS", "Lat", "Lng", "Alt"} <= c.keys():
            has_pos = has_pos or (v[c["Lat"][0]] != 0 or v[c["Lng"][0]] != 0)
        elif fmt.name == "GPS" and boot_utc is None and {"TimeUS", "GWk", "GMS"} <= c.keys():
            if v[c["GWk"][0]] > 0 and ("I" not in c or v[c["I"][0]] == 0):
                gps = dataflash.gps_utc(v[c["GWk"][0]], v[c["GMS"][0]])
                boot_utc = gps - v[c["TimeUS"][0]] * 1e-6
        elif fmt.name == "ORGN" and home is None and {"Type", "Alt"} <= c.keys():
            if v[c["Type"][0]] == 1:
                home = dataflash.value(fmt, v, "Alt")
        if boot_utc is not None and has_pos and home is not None:
            break
    return boot_utc, bool(has_pos), home


def _dataflash(path, info, sysid, size):
    boot_utc, has_pos, home = _dataflash_survey(path, info)
    info.source = "POS" if has_pos else "GPS"
    if boot_utc is None:
        info.clock = "boot"
        info.notes.append("no GPS time in the log: times are seconds since boot")
    out = _Chunks(size)
    last_t, nan = -np.inf, float("nan")
    for fmt, v in dataflash.messages(path, info, (info.source,)):
        c = fmt.columns
        if not {"TimeUS", "Lat", "Lng", "Alt"} <= c.keys():
            continue
        lat, lon, amsl = (
            dataflash.value(fmt, v, "Lat"),
            dataflash.value(fmt, v, "Lng"),
            dataflash.value(fmt, v, "Alt"),
        )
        t = v[c["TimeUS"][0]] * 1e-6 + (boot_utc or 0.0)
        if fmt.name == "GPS" and (
            ("I" in c and v[c["I"][0]] != 0)
            or ("Status" in c and v[c["Status"][0]] < 3)  # no 3D fix
        ):
            continue
        if (lat == 0 and lon == 0) or t <= last_t:
            info.skipped += 1
            continue
        rel_col = "RelHomeAlt" if "RelHomeAlt" in c else "RelAlt" if "RelAlt" in c else None
        rel = dataflash.value(fmt, v, rel_col) if rel_col else nan
        vn = ve = nan
        if {"Spd", "GCrs"} <= c.keys():
            spd, crs = dataflash.value(fmt, v, "Spd"), np.radians(dataflash.value(fmt, v, "GCrs"))
            vn, ve = spd * np.cos(crs), spd * np.sin(crs)
        if home is None and rel_col is None:
            home = amsl  # the first fix: the vehicle on the ground before take-off
            info.notes.append(
                "no height above home in the log: home taken as the first fix's altitude"
            )
        if rel_col is None:
            rel = amsl - home
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
