"""A small ULog writer for tests: the layout of PX4's dev guide ("ULog File Format"), written
here from that description so that the ULog reader is tested on files whose every sample is
known.

Header: ``ULog`` ``01 12 35``, version 1, a uint64 timestamp. Then messages, each a uint16
payload size and a type byte: ``F`` (a topic's format, ``name:type field;...``), ``A`` (a
subscription: multi id, message id, topic name) and ``D`` (a sample: message id, fields).
"""

from __future__ import annotations

import struct

MAGIC = b"ULog\x01\x12\x35"
TYPES = {"uint64_t": "Q", "double": "d", "float": "f", "bool": "?", "int64_t": "q", "uint8_t": "B"}


def _message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def ulog_bytes(topics: dict) -> bytes:
    """A ULog holding ``topics``: name -> (fields, rows), ``fields`` a list of
    ``(type, name)`` starting with ``("uint64_t", "timestamp")``, ``rows`` tuples of values.
    Samples are written in time order across topics."""
    out = [MAGIC, b"\x01", struct.pack("<Q", 0)]
    for name, (fields, _rows) in topics.items():
        fmt = f"{name}:" + "".join(f"{t} {f};" for t, f in fields)
        out.append(_message(b"F", fmt.encode()))
    samples = []
    for msg_id, (name, (fields, rows)) in enumerate(topics.items()):
        out.append(_message(b"A", struct.pack("<BH", 0, msg_id) + name.encode()))
        layout = "<" + "".join(TYPES[t] for t, _ in fields)
        for row in rows:
            samples.append((row[0], msg_id, struct.pack(layout, *row)))
    for _t, msg_id, data in sorted(samples, key=lambda s: (s[0], s[1])):
        out.append(_message(b"D", struct.pack("<H", msg_id) + data))
    return b"".join(out)


GLOBAL = [("uint64_t", "timestamp"), ("double", "lat"), ("double", "lon"), ("float", "alt"),
          ("bool", "lat_lon_valid")]  # fmt: skip
LOCAL = [("uint64_t", "timestamp"), ("float", "vx"), ("float", "vy")]
HOME = [("uint64_t", "timestamp"), ("double", "lat"), ("double", "lon"), ("float", "alt")]
GPS = [("uint64_t", "timestamp"), ("uint64_t", "time_utc_usec")]
