"""Parameter values as PARAM_SET and PARAM_VALUE carry them: a float field either way.

ArduPilot sends an integer parameter as that number in the float (``5`` as ``5.0``). PX4
copies its bytes instead (MAVLink's byte-wise encoding, which its AUTOPILOT_VERSION announces
with ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``): ``GF_ACTION = 2`` travels as the float
whose bits are the int32 2. Read the ArduPilot way, PX4's integers come out as tiny floats;
written the ArduPilot way, ``2.0`` lands in PX4 as 1073741824, and reads back as ``2.0`` the
same wrong way: a read-back alone would not see it.

Examples
--------
>>> wire = encode(2, INT32, bytewise=True)
>>> wire == 2.0, decode(wire, INT32, bytewise=True)
(False, 2.0)
>>> decode(encode(2, INT32, bytewise=False), INT32, bytewise=False)
2.0
"""

from __future__ import annotations

import struct

from alphafence.mavlink import ids

INT32 = ids.MAV_PARAM_TYPE_INT32
REAL32 = ids.MAV_PARAM_TYPE_REAL32
_INTEGER_TYPES = range(1, 7)  # MAV_PARAM_TYPE_UINT8 .. MAV_PARAM_TYPE_INT32


def encode(value, param_type: int, bytewise: bool) -> float:
    """The float a PARAM_SET carries for ``value`` of ``param_type``."""
    if bytewise and param_type in _INTEGER_TYPES:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode(wire: float, param_type: int, bytewise: bool) -> float:
    """The value a PARAM_VALUE's float ``wire`` of ``param_type`` stands for."""
    if bytewise and param_type in _INTEGER_TYPES:
        return float(struct.unpack("<i", struct.pack("<f", wire))[0])
    return float(wire)
