"""ArduPilot DataFlash logs (``.BIN``) streamed: the messages a reader wants, decoded as
pymavlink's ``DFReader`` decodes them, everything else skipped by its length.

A log is a sequence of messages: ``0xA3 0x95``, a type byte, then the fields the type's ``FMT``
message declared (name, length, format characters, column names; FMT itself is type 128, 89
bytes). The format characters are read with pymavlink's own table
(``DFReader.FORMAT_TO_STRUCT``: struct codes and multipliers, e.g. ``L`` int32 degrees * 1e7).
Corrupt bytes are skipped to the next header, as ``DFReader`` does; a last message cut short is
reported (``truncated``). Only a block of the file is held at a time.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

BLOCK = 1 << 20  # bytes read at a time
HEAD = b"\xa3\x95"
FMT_TYPE, FMT_LEN = 0x80, 89
GPS_EPOCH = 315964800  # 1980-01-06T00:00:00Z in UNIX seconds
# GPS time - UTC (leap seconds), from the UNIX time each value began
LEAP_SECONDS = ((1136073600, 14), (1230768000, 15), (1341100800, 16), (1435708800, 17))
LEAP_SECONDS += ((1483228800, 18),)


@dataclass
class _Format:
    name: str
    length: int
    unpack: object  # struct.Struct.unpack_from, or None for a type whose fields are unknown
    columns: dict  # column name -> (index, multiplier or None)


def _format(ftype, length, name, fmt, columns):
    """A DataFlash message type from its FMT fields, with pymavlink's type table."""
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    name = name.split(b"\0")[0].decode("ascii", "replace")
    fmt = fmt.split(b"\0")[0].decode("ascii", "replace")
    cols = columns.split(b"\0")[0].decode("ascii", "replace").split(",")
    try:
        spec = [FORMAT_TO_STRUCT[c] for c in fmt]
        layout = struct.Struct("<" + "".join(s for s, _, _ in spec))
    except (KeyError, struct.error):
        return _Format(name, length, None, {})
    if layout.size != length - 3 or len(cols) != len(spec):
        return _Format(name, length, None, {})
    return _Format(
        name, length, layout.unpack_from, {c: (k, spec[k][1]) for k, c in enumerate(cols)}
    )


def value(fmt, values, column):
    """A field as pymavlink's ``DFMessage`` gives it (multipliers below 1 applied by division).

    Parameters
    ----------
    fmt : object
        The message's format, as :func:`messages` yields it (``columns``: name -> (index,
        multiplier)).
    values : tuple
        The message's raw fields.
    column : str
        The field's name (``"Lat"``).

    Returns
    -------
    int or float or bytes
    """
    k, mult = fmt.columns[column]
    v = values[k]
    if mult is None:
        return v
    return v / (1 / mult) if 0.0 < mult < 1.0 else v * mult


def messages(path, info, wanted):
    """The messages of a DataFlash log whose type is named in ``wanted``, streamed.

    Parameters
    ----------
    path : str or Path
    info : object
        Counts what was read: ``messages``, ``bad_bytes`` (skipped to the next header) and
        ``truncated`` (the last message is cut short) are updated.
    wanted : collection of str
        Message names (``"POS"``, ``"GPS"``).

    Yields
    ------
    (format, tuple)
        The message's format (``name``, ``columns``) and its raw fields; read them with
        :func:`value`.
    """
    fmt_layout = struct.Struct("<BB4s16s64s")
    formats = {FMT_TYPE: _Format("FMT", FMT_LEN, None, {})}
    with open(path, "rb") as fh:
        buf, pos, eof = b"", 0, False
        while True:
            if len(buf) - pos < 256 and not eof:  # the longest message is 255 bytes
                more = fh.read(BLOCK)
                eof = not more
                buf, pos = buf[pos:] + more, 0
            if len(buf) - pos < 3:
                info.bad_bytes += len(buf) - pos
                return
            if buf[pos] != 0xA3 or buf[pos + 1] != 0x95:
                j = buf.find(HEAD, pos + 1)
                skip = (j if j >= 0 else len(buf) - 1) - pos
                info.bad_bytes += skip
                pos += skip
                continue
            fmt = formats.get(buf[pos + 2])
            if fmt is None:  # a type no FMT defined: not a message start
                info.bad_bytes += 1
                pos += 1
                continue
            end = pos + fmt.length
            if end > len(buf):
                info.truncated = True
                return
            info.messages += 1
            if buf[pos + 2] == FMT_TYPE:
                ftype, length, name, f, cols = fmt_layout.unpack_from(buf, pos + 3)
                if length >= 3 and ftype != FMT_TYPE:
                    formats[ftype] = _format(ftype, length, name, f, cols)
            elif fmt.name in wanted and fmt.unpack is not None:
                yield fmt, fmt.unpack(buf, pos + 3)
            pos = end


def gps_utc(week, ms) -> float:
    """UNIX time (UTC) of a GPS week and milliseconds into it: GPS time less the leap seconds
    GPS time was ahead of UTC then.

    Examples
    --------
    >>> from datetime import datetime, timezone
    >>> datetime.fromtimestamp(gps_utc(2342, 432018000), timezone.utc).isoformat()
    '2024-11-29T00:00:00+00:00'
    """
    t = GPS_EPOCH + week * 604800 + ms * 1e-3
    leap = next((s for start, s in reversed(LEAP_SECONDS) if t - s >= start), 13)
    return t - leap
