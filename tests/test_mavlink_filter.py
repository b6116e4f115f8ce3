"""The link's filter: with ``wanted_ids`` set, frames of other ids are framed from their header
and dropped unread, and what is delivered is exactly what a full parse delivers of the wanted ids
(signed or not, MAVLink 1 or 2, noise between frames, any chunking of a serial stream)."""

from __future__ import annotations

import hypothesis.strategies as st
from hypothesis import HealthCheck, given, settings
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from alphafence.mavlink.udp import MavlinkDatagrams
from alphafence.vehicle.bridge import MESSAGE_IDS, VehicleLink
from alphafence.vehicle.keys import signing_timestamp

KEY = bytes(range(32))
WANTED = {"HEARTBEAT", "GLOBAL_POSITION_INT"}


def _sender(signed: bool, v1: bool = False):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    if v1:
        mav.WIRE_PROTOCOL_VERSION = "1.0"
        mav.protocol_marker = mavlink.PROTOCOL_MARKER_V1
        mav.mavlink20 = lambda: False
    if signed:
        mav.signing.secret_key = KEY
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = signing_timestamp() + 1000  # ahead of the link's clock
    return mav


def _frame(mav, kind: int, i: int) -> bytes:
    if kind == 0:
        return mav.heartbeat_encode(2, 3, 0, 0, 4).pack(mav)
    if kind == 1:
        return mav.global_position_int_encode(
            i, 359000000 + i, 144000000, 50000, 20000, 0, 0, 0, 0
        ).pack(mav)
    if kind == 2:
        return mav.attitude_encode(i, 0.1, 0.2, 0.3, 0, 0, 0).pack(mav)
    if kind == 3:
        return mav.vfr_hud_encode(1.0, 2.0, 90, 50, 20.0, 0.5).pack(mav)
    return mav.statustext_encode(6, b"hello %d" % i).pack(mav)


def _delivered(chunks, wanted_ids, key=None):
    codec = mavlink.MAVLink(None)
    if key is not None:
        codec.signing.secret_key = key
    got, bad = [], []
    wire = MavlinkDatagrams(
        codec, lambda m, a: got.append(m.get_msgbuf()), lambda m, a: bad.append(m)
    )
    wire.wanted_ids = wanted_ids
    for chunk in chunks:
        wire.feed(chunk, ("127.0.0.1", 1))
    return got, wire


frames = st.lists(
    st.tuples(st.integers(0, 4), st.sampled_from(["v2", "v1", "noise"]), st.binary(max_size=6)),
    max_size=40,
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames, st.booleans(), st.lists(st.integers(1, 64), max_size=20))
def test_the_filter_delivers_what_a_full_parse_delivers_of_the_wanted_ids(items, signed, cuts):
    v2, v1 = _sender(signed), _sender(False, v1=True)
    stream = bytearray()
    unwanted = 0
    for i, (kind, form, noise) in enumerate(items):
        if form == "noise":
            # bytes that are not MAVLink (no marker in them), between frames
            stream += bytes(b for b in noise if b not in (0xFD, 0xFE))
            continue
        stream += _frame(v2 if form == "v2" else v1, kind, i)
        unwanted += kind not in (0, 1)
    # a serial stream cut anywhere, and the same bytes as one datagram
    chunks, at = [], 0
    for n in cuts:
        chunks.append(bytes(stream[at : at + n]))
        at += n
    chunks.append(bytes(stream[at:]))
    key = KEY if signed else None
    ids = {MESSAGE_IDS[n] for n in WANTED}
    full, _ = _delivered(chunks, None, key)
    want = [f for f in full if f[5 if f[0] == 0xFE else 7] in ids]
    filtered, wire = _delivered(chunks, ids, key)
    assert filtered == want
    assert wire.skipped == unwanted


def test_a_corrupt_wanted_frame_is_still_rejected_and_an_unwanted_one_never_delivered():
    mav = _sender(False)
    good = _frame(mav, 1, 7)
    corrupt = bytearray(good)
    corrupt[12] ^= 0xFF  # a payload byte: the CRC no longer matches
    other = _frame(mav, 2, 8)
    got, wire = _delivered([bytes(corrupt) + other + good], {MESSAGE_IDS["GLOBAL_POSITION_INT"]})
    assert got == [good]
    assert wire.skipped == 1


def test_a_wrong_key_is_still_noticed_through_the_filter():
    """Dropped frames are not checked, but the wanted ones are: a vehicle signing with another
    key is diagnosed from its heartbeats as before."""
    link = VehicleLink("udpin:127.0.0.1:14999", key=bytes(32))
    link.wanted_ids = {MESSAGE_IDS["HEARTBEAT"]}
    mav = _sender(True)
    link._received(_frame(mav, 0, 0) + _frame(mav, 2, 1), ("127.0.0.1", 1))
    assert link.stats.received == 0
    assert link.stats.bad_signature == 1
    assert link.skipped == 1
    assert "another key" in link.stats.diagnosis(True)


def test_an_unsigned_links_recorder_gets_the_dropped_frames_too_a_signed_ones_only_verified():
    for key, expect_skipped in ((None, True), (KEY, False)):
        link = VehicleLink("udpin:127.0.0.1:14999", key=key)
        link.wanted_ids = {MESSAGE_IDS["HEARTBEAT"]}
        frames = []
        link.recorder = frames.append
        mav = _sender(key is not None)
        beat, other = _frame(mav, 0, 0), _frame(mav, 3, 1)
        link._received(beat + other, ("127.0.0.1", 1))
        assert [bytes(f) for f in frames] == ([beat, other] if expect_skipped else [beat])
