"""The few messages read at rate, decoded straight from their MAVLink 2 frames.

The monitor reads GLOBAL_POSITION_INT 10 to 50 times a second; pymavlink's general decoder
(a message object, its fields set one by one, its CRC and signature checked through several
calls) costs more than everything else the monitor does with a position far from fences.
:class:`FrameDecoder` does for one message type what pymavlink does, with the numbers taken
from pymavlink's own class for it (id, CRC_EXTRA, payload layout): the frame's CRC-16/MCRF4XX
over header and payload plus CRC_EXTRA, MAVLink 2's truncated payload padded with zeros, then
one precompiled ``struct`` unpack. On a link with a signing key, the frame must also carry a
signature made with the key whose timestamp moves forward on its stream (pymavlink's rule,
sharing pymavlink's own record of each stream's timestamps, so either decoder may read the
next frame); the signature is checked before the timestamp is recorded.

A frame this decoder does not accept (a bad CRC, no or a wrong signature, an old timestamp,
MAVLink 1) is not dropped here: the link hands it to pymavlink, which rejects it and counts
why, exactly as before. So this path only ever delivers what pymavlink would have delivered
(``tests/test_fast_frames.py`` compares the two on random and corrupted frames).
"""

from __future__ import annotations

import hashlib

from pymavlink.generator import mavcrc
from pymavlink.generator.mavcrc import x25crc

mcrf4xx = getattr(mavcrc, "mcrf4xx", None)  # fastcrc's, when pymavlink found it

MARKER_V2 = 0xFD
HEADER_V2 = 10  # marker, length, incompat and compat flags, sequence, system, component, id
SIGNATURE_BYTES = 13  # link id, 6 bytes of timestamp, 6 of signature
NEW_STREAM_WINDOW = 6000 * 1000  # pymavlink: a new stream at most a minute (10 us units) behind


class FrameDecoder:
    """One MAVLink message type, decoded from whole MAVLink 2 frames.

    Parameters
    ----------
    cls : pymavlink message class
        e.g. ``ardupilotmega.MAVLink_global_position_int_message``: its ``id``,
        ``crc_extra``, ``unpacker`` and ``ordered_fieldnames`` say everything.

    Attributes
    ----------
    index : dict
        ``{field name: its position in the decoded tuple}``.
    """

    def __init__(self, cls):
        self.msgid = cls.id
        self.extra = bytes([cls.crc_extra])
        self.unpack = cls.unpacker.unpack
        self.size = cls.unpacker.size
        self.index = {name: i for i, name in enumerate(cls.ordered_fieldnames)}
        if any(getattr(cls, "array_lengths", ())):
            raise ValueError(f"{cls.__name__}: array fields are not decoded here")

    def decode(self, frame: bytes, signing=None) -> tuple | None:
        """The fields (in wire order) of one whole MAVLink 2 frame of this type, or None
        when pymavlink is to judge it.

        Parameters
        ----------
        frame : bytes
            From the marker to the last byte (the signature's, when it carries one).
        signing : pymavlink MAVLinkSigning, optional
            The reader's signing state when the link verifies signatures (then an unsigned
            frame, a wrong signature or an old timestamp is not accepted here).
        """
        n = frame[1]
        end = HEADER_V2 + n
        signed = frame[2] & 1
        if len(frame) != end + 2 + (SIGNATURE_BYTES if signed else 0) or n > self.size:
            return None
        if (
            frame[0] != MARKER_V2
            or frame[2] > 1
            or frame[7] | frame[8] << 8 | frame[9] << 16 != self.msgid
        ):
            return None
        if _crc(frame, end, self.extra) != frame[end] | frame[end + 1] << 8:
            return None
        if signing is not None and not (signed and _signed_by(frame, signing)):
            return None
        payload = frame[HEADER_V2:end]
        if n < self.size:  # MAVLink 2 drops trailing zero bytes
            payload += bytes(self.size - n)
        return self.unpack(payload)


def _crc(frame, end, extra) -> int:
    """CRC-16/MCRF4XX of the header after the marker and the payload, then CRC_EXTRA: by
    fastcrc straight on the frame where pymavlink uses it, else by pymavlink's own class."""
    if mcrf4xx is not None:
        return mcrf4xx(extra, mcrf4xx(memoryview(frame)[1:end], 0xFFFF))
    return x25crc(frame[1:end] + extra).crc


def check_signature(signing, msgbuf, src_system=None, src_component=None) -> bool:
    """pymavlink's ``MAVLink.check_signature`` with the signature checked first: pymavlink
    records a frame's timestamp for its stream before it checks the signature, so one forged
    frame stamped far ahead makes every genuine frame of that stream "old" (a link lost to a
    single unsigned-key packet). Bind it to a reader with ``functools.partial(check_signature,
    reader.signing)`` as ``reader.check_signature``."""
    return _signed_by(bytes(msgbuf), signing)


def _signed_by(frame: bytes, signing) -> bool:
    """Whether ``frame`` is signed with the key and its timestamp moves its stream forward;
    if so the timestamp is recorded (as pymavlink's ``check_signature`` records it)."""
    digest = hashlib.sha256(signing.secret_key + frame[:-6]).digest()
    if digest[:6] != frame[-6:]:
        return False
    stamp = int.from_bytes(frame[-12:-6], "little")
    stream = (frame[-13], frame[5], frame[6])  # link id, system, component
    last = signing.stream_timestamps.get(stream)
    if last is not None and stamp <= last:
        return False
    if last is None and stamp + NEW_STREAM_WINDOW < signing.timestamp:
        return False
    signing.stream_timestamps[stream] = stamp
    signing.timestamp = max(signing.timestamp, stamp)
    return True
