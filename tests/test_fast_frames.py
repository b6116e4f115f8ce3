"""GLOBAL_POSITION_INT decoded straight from its frames (alphafence.vehicle.fast_frames) gives
what pymavlink gives, and accepts nothing pymavlink would reject: random field values and
truncated payloads, corrupted bytes, signatures with the wrong key, replayed timestamps,
unsigned frames on a signed link; through the link, in order among other messages. A decoder
that skips the CRC is caught by the same corruption."""

from __future__ import annotations

import hypothesis.strategies as st
from hypothesis import given, settings
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from alphafence.mavlink.udp import MavlinkDatagrams
from alphafence.vehicle import fast_frames
from alphafence.vehicle.fast_frames import FrameDecoder
from alphafence.vehicle.keys import signing_timestamp

KEY = bytes(range(32))
GPI = mavlink.MAVLink_global_position_int_message

fields = st.tuples(
    st.integers(0, 2**32 - 1),
    *[st.integers(-(2**31), 2**31 - 1)] * 4,
    *[st.integers(-(2**15), 2**15 - 1)] * 3,
    st.integers(0, 2**16 - 1),
)


def sender(key=None, system=1):
    mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=1)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = signing_timestamp() + 1000
    return mav


def reader(key=None):
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.timestamp = signing_timestamp()
    return mav


def by_pymavlink(codec, frame):
    msgs = [m for m in codec.parse_buffer(frame) or [] if m.get_type() != "BAD_DATA"]
    return tuple(getattr(msgs[0], f) for f in GPI.ordered_fieldnames) if msgs else None


DECODER = FrameDecoder(GPI)


def fast(codec, frame, decoder=DECODER):
    signing = codec.signing if codec.signing.secret_key is not None else None
    return decoder.decode(frame, signing)


@settings(max_examples=300, deadline=None)
@given(values=fields, signed=st.booleans())
def test_a_good_frame_decodes_as_pymavlink_decodes_it(values, signed):
    key = KEY if signed else None
    frame = GPI(*values).pack(sender(key))
    assert fast(reader(key), frame) == by_pymavlink(reader(key), frame) == values


@settings(max_examples=400, deadline=None)
@given(values=fields, signed=st.booleans(), at=st.integers(1, 60), bit=st.integers(0, 7))
def test_a_corrupted_frame_is_never_accepted_where_pymavlink_rejects_it(values, signed, at, bit):
    key = KEY if signed else None
    frame = bytearray(GPI(*values).pack(sender(key)))
    at %= len(frame)
    frame[at] ^= 1 << bit
    frame = bytes(frame)
    got = fast(reader(key), frame)
    if got is not None:  # then pymavlink accepts it too, with the same fields
        assert got == by_pymavlink(reader(key), frame)
    if at >= 10 and at < len(frame) - (13 if signed else 0):  # a payload or CRC byte
        assert got is None


def test_without_fastcrc_pymavlinks_own_crc_class_checks_frames(monkeypatch):
    monkeypatch.setattr(fast_frames, "mcrf4xx", None)
    frame = GPI(1, 359000000, 144000000, 5, 6, 7, 8, 9, 10).pack(sender())
    assert fast(reader(), frame) == (1, 359000000, 144000000, 5, 6, 7, 8, 9, 10)
    bad = bytearray(frame)
    bad[14] ^= 0x10
    assert fast(reader(), bytes(bad)) is None


def test_signatures_are_checked_before_the_stream_moves_on():
    frame = GPI(*[1] * 9).pack(sender(bytes(32)))  # signed with another key
    codec = reader(KEY)
    assert fast(codec, frame) is None
    assert codec.signing.stream_timestamps == {}  # a forged frame moves no stream
    mav = sender(KEY)
    first = GPI(*[1] * 9).pack(mav)
    assert fast(codec, first) is not None
    assert fast(codec, first) is None  # replayed
    assert fast(codec, GPI(*[2] * 9).pack(mav)) is not None
    unsigned = GPI(*[3] * 9).pack(sender())
    assert fast(codec, unsigned) is None  # on a signed link


def test_a_decoder_that_skips_the_crc_accepts_corruption(monkeypatch):
    # broken on purpose: with the CRC comparison gone, a flipped payload bit is delivered
    frame = bytearray(GPI(1, 359000000, 144000000, 5, 6, 7, 8, 9, 10).pack(sender()))
    frame[14] ^= 0x10
    assert fast(reader(), bytes(frame)) is None

    monkeypatch.setattr(fast_frames, "_crc", lambda f, end, extra: f[end] | f[end + 1] << 8)
    assert fast(reader(), bytes(frame)) is not None


def delivered(data, key, with_fast):
    """What a link's wire delivers of ``data``: ``(type, time_boot_ms or None)`` in order."""
    got, rejected = [], []
    codec = reader(key)

    def message(m, addr):
        got.append((m.get_type(), getattr(m, "time_boot_ms", None)))

    wire = MavlinkDatagrams(codec, message, lambda m, a: rejected.append(m))
    wire.wanted_ids = {0, GPI.id}
    decoder = FrameDecoder(GPI)

    def take(frame, addr):
        values = fast(codec, frame, decoder)
        if values is not None:
            got.append(("GLOBAL_POSITION_INT", values[0]))
        return values is not None

    if with_fast:
        wire.fast[GPI.id] = take
    wire.feed(data)
    return got, len(rejected)


@settings(max_examples=200, deadline=None)
@given(
    kinds=st.lists(st.sampled_from(["heartbeat", "gpi", "bad", "noise"]), min_size=1, max_size=12),
    signed=st.booleans(),
)
def test_the_link_delivers_what_pymavlink_alone_delivers(kinds, signed):
    key = KEY if signed else None
    mav = sender(key)
    data = b""
    for i, kind in enumerate(kinds):
        if kind == "heartbeat":
            data += mav.heartbeat_encode(2, 3, 0, 0, 4).pack(mav)
        elif kind == "noise":
            data += b"\x00\x01 not mavlink"
        else:
            frame = bytearray(GPI(i, 2, 3, 4, 5, 6, 7, 8, 9).pack(mav))
            if kind == "bad":
                frame[12] ^= 1
            data += bytes(frame)
    assert delivered(data, key, True) == delivered(data, key, False)
    assert (
        any(kind == "gpi" for kind in kinds)
        <= any(t == "GLOBAL_POSITION_INT" for t, _ in delivered(data, key, True)[0])
        or "bad" in kinds
        or "noise" in kinds
    )


def _first_of_stream(behind, key=KEY):
    """A new stream's first frame stamped ``behind`` (10 us units) before the reader's clock,
    read by both decoders: (fast's verdict, pymavlink's)."""
    now = signing_timestamp()
    mav = sender(key)
    mav.signing.timestamp = now - behind
    frame = GPI(*[4] * 9).pack(mav)
    assert int.from_bytes(frame[-12:-6], "little") == now - behind
    ours, theirs = reader(key), reader(key)
    ours.signing.timestamp = theirs.signing.timestamp = now
    return fast(ours, frame) is not None, by_pymavlink(theirs, frame) is not None


def test_a_new_stream_more_than_a_minute_behind_is_refused_as_pymavlink_refuses_it():
    # MAVLink 2 signing (pymavlink's check_signature): a stream's first timestamp may be at
    # most 60 s, 6,000,000 units of 10 us, behind the link's own; one unit more is a replay
    minute = 60 * 100_000
    assert _first_of_stream(0) == (True, True)
    assert _first_of_stream(minute) == (True, True)
    assert _first_of_stream(minute + 1) == (False, False)
    assert _first_of_stream(10 * minute) == (False, False)


def test_a_decoder_without_the_new_stream_window_takes_an_old_recording(monkeypatch):
    # broken on purpose: with no window, a recording hours old opens a stream
    monkeypatch.setattr(fast_frames, "NEW_STREAM_WINDOW", 10**15)
    assert _first_of_stream(360 * 60 * 100_000) == (True, False)


def test_one_forged_frame_stamped_ahead_does_not_lock_out_the_vehicles_stream():
    # a frame signed with another key, on the vehicle's stream (link 0, system 1, component
    # 1), stamped an hour ahead: the link's reader checks the signature before it moves the
    # stream, so the vehicle's next genuine frame is still taken. pymavlink alone (the
    # broken case) records the forged stamp first and drops the vehicle from then on.
    from alphafence.vehicle.bridge import VehicleLink

    forger = sender(bytes(32))
    forger.signing.timestamp = signing_timestamp() + 360_000_000
    forged = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(forger)
    genuine = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(sender(KEY))

    got = []
    link = VehicleLink("udpout://127.0.0.1:9", KEY, got.append, verify=True)
    link._received(forged, ("127.0.0.1", 1))
    link._received(genuine, ("127.0.0.1", 1))
    assert len(got) == 1 and link.stats.bad_signature == 1

    alone = reader(KEY)
    assert not [m for m in alone.parse_buffer(forged) or [] if m.get_type() == "HEARTBEAT"]
    assert not [m for m in alone.parse_buffer(genuine) or [] if m.get_type() == "HEARTBEAT"]


def _recrc(frame, extra):
    """``frame`` with its CRC made again over its header and payload (and ``extra``): a frame
    whose every other check must stand on its own."""
    from pymavlink.generator.mavcrc import x25crc

    frame = bytearray(frame)
    end = 10 + frame[1]
    crc = x25crc(bytes(frame[1:end]) + bytes([extra])).crc
    frame[end], frame[end + 1] = crc & 0xFF, crc >> 8
    return bytes(frame)


def test_a_frame_is_decoded_only_as_its_own_message_id():
    # a GLOBAL_POSITION_INT frame carried under another id (each byte of the 24-bit id in
    # turn), its CRC made good with GLOBAL_POSITION_INT's extra: the id alone refuses it
    frame = GPI(1, 359000000, 144000000, 5, 6, 7, 8, 9, 10).pack(sender())
    extra = GPI.crc_extra
    assert fast(reader(), _recrc(frame, extra)) is not None
    for at, value in ((7, 34), (8, 1), (9, 1)):
        other = bytearray(frame)
        other[at] = value
        assert fast(reader(), _recrc(bytes(other), extra)) is None, at
    # and a decoder for an id above 255 (two id bytes) takes its own frames
    cls = mavlink.MAVLink_button_change_message
    mine = cls(1, 2, 3).pack(sender())
    assert FrameDecoder(cls).decode(mine) == (1, 2, 3)


def test_a_frame_with_unknown_incompatibility_flags_or_marker_is_refused():
    # MAVLink 2: an incompat_flags bit other than signing's means "do not parse"; a frame
    # that does not start with 0xFD is no MAVLink 2 frame, whatever its CRC says
    frame = GPI(1, 2, 3, 4, 5, 6, 7, 8, 9).pack(sender())
    for at, value in ((2, 2), (2, 4), (2, 0x80), (0, 0xFE)):
        other = bytearray(frame)
        other[at] = value
        other = _recrc(bytes(other), GPI.crc_extra)
        assert fast(reader(), other) is None, (at, value)
        assert by_pymavlink(reader(), other) is None, (at, value)
    # compat_flags are ignored by a reader that does not know them
    other = bytearray(frame)
    other[3] = 0x10
    assert fast(reader(), _recrc(bytes(other), GPI.crc_extra)) is not None


def test_each_link_system_and_component_is_a_stream_of_its_own():
    # signing: a timestamp must move forward on its own stream (link id, system, component);
    # a newer stream elsewhere does not make an older stamp here a replay
    codec = reader(KEY)
    first = sender(KEY, system=1)
    first.signing.timestamp += 1000
    assert fast(codec, GPI(*[1] * 9).pack(first)) is not None
    for system, component, link in ((2, 1, 0), (1, 2, 0), (1, 1, 3)):
        other = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
        other.signing.secret_key, other.signing.sign_outgoing = KEY, True
        other.signing.link_id = link
        other.signing.timestamp = first.signing.timestamp - 500
        frame = GPI(*[2] * 9).pack(other)
        assert fast(codec, frame) is not None, (system, component, link)
        assert fast(codec, frame) is None  # and replayed there, refused
    # on the first stream, another frame stamped before its last is refused too
    older = sender(KEY, system=1)
    older.signing.timestamp = first.signing.timestamp - 10
    frame = GPI(*[3] * 9).pack(older)
    assert fast(codec, frame) is None
    assert fast(reader(KEY), frame) is not None  # (new to a fresh reader: the stamp is why)


def test_the_decoder_names_its_fields_and_refuses_arrays():
    decoder = FrameDecoder(GPI)
    assert decoder.index == {name: k for k, name in enumerate(GPI.ordered_fieldnames)}
    assert decoder.index["lat"] == 1
    import pytest

    with pytest.raises(ValueError, match="MAVLink_param_value_message: array fields"):
        FrameDecoder(mavlink.MAVLink_param_value_message)
