"""MAVLink 2 signing: key files, the signed link (alphafence.vehicle.bridge) and SETUP_SIGNING, against
the scripted ArduPilot peer (tests/fake_vehicle.py) acting as ArduPilot's channel 1: with a key
it signs what it sends and drops whatever is not signed with it.

The same behaviour on real ArduPilot SITL is tests/test_signing_sitl.py."""

from __future__ import annotations

import hashlib
import os
import stat

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.vehicle.bridge import VehicleLink, is_signed, signature_matches
from alphafence.vehicle.endpoints import EndpointError
from alphafence.vehicle.fence_transfer import FenceTransferError, upload_fence
from alphafence.vehicle.keys import load_key, signing_timestamp, write_new_key
from alphafence.vehicle.link import LinkError, open_vehicle
from alphafence.vehicle.signing import SigningSetupError, install_key
from tests.fake_vehicle import FakeVehicle
from tests.test_upload_faults import NEW, PREVIOUS

KEY = bytes(range(1, 33))
OTHER = bytes(range(101, 133))


# -- key files ---------------------------------------------------------------------------


def test_key_file_hex_and_passphrase(tmp_path):
    hexfile = tmp_path / "k.hex"
    hexfile.write_text(KEY.hex().upper() + "\n")
    assert load_key(hexfile) == KEY
    phrase = tmp_path / "k.txt"
    phrase.write_text("correct horse battery staple\n")
    # MAVProxy's `signing setup PASSPHRASE`: the key is SHA-256 of the passphrase
    assert load_key(phrase) == hashlib.sha256(b"correct horse battery staple").digest()


@pytest.mark.parametrize(
    "content, says",
    [
        (b"", "empty"),
        (b"one\ntwo\n", "one line"),
        (b"\xff\xfe\x00", "UTF-8"),
        (b"0" * 64, "all-zero"),
        (b"x" * 5000, "over 4 KB"),
    ],
)
def test_bad_key_files_are_one_line_errors(tmp_path, content, says):
    path = tmp_path / "key"
    path.write_bytes(content)
    with pytest.raises(InputError) as err:
        load_key(path)
    assert says in str(err.value) and str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_keygen_is_private_random_and_never_overwrites(tmp_path):
    path = tmp_path / "vehicle.key"
    key = write_new_key(path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert load_key(path) == key and len(key) == 32
    assert write_new_key(tmp_path / "second.key") != key
    with pytest.raises(InputError, match="refusing to overwrite"):
        write_new_key(path)
    assert load_key(path) == key
    assert sorted(p.name for p in tmp_path.iterdir()) == ["second.key", "vehicle.key"]


def test_cli_keygen(tmp_path, capsys):
    path = tmp_path / "k"
    assert main(["signing", "keygen", str(path)]) == 0
    assert len(load_key(path)) == 32
    assert main(["signing", "keygen", str(path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err


def test_timestamp_counts_10us_since_2015():
    assert signing_timestamp(1420070400.0) == 0
    assert signing_timestamp(1420070400.0 + 1.5) == 150_000


def test_the_signed_link_takes_every_connection_form():
    for url, kind in [
        ("udpin://:14550", "udpin"),
        ("udpin:0.0.0.0:14550", "udpin"),
        ("tcpout://navio.local:5760", "tcpout"),
        ("tcp:navio.local:5760", "tcpout"),
        ("tcpin:0.0.0.0:5760", "tcpin"),
        ("serial:///dev/ttyAMA0:57600", "serial"),  # was refused: "a signed link runs over udpin"
        ("/dev/ttyACM0", "serial"),
    ]:
        assert VehicleLink(url, KEY).endpoint.kind == kind
    for bad, says in [
        ("udpout://:14550", "vehicle's address"),
        ("udpin://0.0.0.0:70000", "outside 1..65535"),
    ]:
        with pytest.raises(EndpointError, match=says):
            VehicleLink(bad, KEY)


# -- signatures on the wire --------------------------------------------------------------


def _signed_heartbeat(key, timestamp):
    sender = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    sender.signing.secret_key = key
    sender.signing.sign_outgoing = True
    sender.signing.timestamp = timestamp
    return sender.heartbeat_encode(2, 3, 0, 0, 4).pack(sender)


def _tampered(frame):
    """One payload bit changed, the CRC made right again, the signature kept (a forgery)."""
    buf = bytearray(frame)
    n = buf[1]
    buf[10] ^= 0x01
    crc = mav.x25crc(bytes(buf[1 : 10 + n]))
    crc.accumulate(bytes([mav.MAVLink_heartbeat_message.crc_extra]))
    buf[10 + n : 12 + n] = crc.crc.to_bytes(2, "little")
    return bytes(buf)


def test_link_accepts_only_fresh_messages_signed_with_its_key():
    got = []
    link = VehicleLink("udpout://127.0.0.1:9", KEY, got.append)
    ts = signing_timestamp()
    good = _signed_heartbeat(KEY, ts)
    assert is_signed(good) and signature_matches(good, KEY) and not signature_matches(good, OTHER)
    link._received(good, None)
    assert len(got) == 1
    link._received(good, None)  # replayed: same timestamp
    link._received(_tampered(_signed_heartbeat(KEY, ts + 10)), None)
    link._received(_signed_heartbeat(OTHER, ts + 20), None)
    unsigned = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    link._received(unsigned.heartbeat_encode(2, 3, 0, 0, 4).pack(unsigned), None)
    assert len(got) == 1
    assert link.stats.unsigned == 1
    assert link.stats.bad_signature == 3 and link.stats.garbage == 0
    # our own timestamps follow the vehicle's clock (SITL's runs ahead at a speedup)
    link._received(_signed_heartbeat(KEY, ts + 10**9), None)
    assert len(got) == 2 and link.mav.signing.timestamp >= ts + 10**9


# -- the signed link end to end, on each link (MAVSDK -> bridge, or pymavlink's own signing) --


async def test_signed_upload_succeeds_and_is_signed_on_the_wire(link):
    async with FakeVehicle(fence=PREVIOUS, signing_key=KEY) as fake:
        async with open_vehicle(fake.url, 10, signing_key=KEY) as vehicle:
            await upload_fence(vehicle, NEW)
            stats = vehicle.link_stats()
        assert [it.lat for it in fake.fence] == [it.lat for it in NEW]
        assert fake._mav.signing.goodsig_count > 0  # the fake checked our signatures
        assert fake.dropped == 0
        assert stats.unsigned == stats.bad_signature == 0


async def test_wrong_key_is_refused_and_the_fence_is_unchanged(link):
    async with FakeVehicle(fence=PREVIOUS, signing_key=KEY) as fake:
        with pytest.raises(LinkError, match="signed with another key"):
            async with open_vehicle(fake.url, 3, signing_key=OTHER):
                pass
        assert fake.received("MISSION_COUNT") == [] and fake.fence_writes == 0
        assert [it.lat for it in fake.fence] == [it.lat for it in PREVIOUS]


async def test_missing_key_upload_fails_and_the_fence_is_unchanged(link):
    async with FakeVehicle(fence=PREVIOUS, signing_key=KEY, upload_timeout=2.0) as fake:
        async with open_vehicle(fake.url, 10) as vehicle:  # MAVSDK sees the signed heartbeats
            with pytest.raises(FenceTransferError) as err:
                await upload_fence(vehicle, NEW)
        assert err.value.result == "TIMEOUT"
        assert fake.received("MISSION_COUNT") == []  # dropped unsigned, never handled
        assert fake.dropped > 0
        assert [it.lat for it in fake.fence] == [it.lat for it in PREVIOUS]


async def test_key_given_but_vehicle_does_not_sign(link):
    async with FakeVehicle(fence=PREVIOUS) as fake:
        with pytest.raises(LinkError, match="does not sign its messages"):
            async with open_vehicle(fake.url, 2, signing_key=KEY):
                pass


# -- SETUP_SIGNING -----------------------------------------------------------------------


async def test_install_change_and_remove_a_key():
    async with FakeVehicle(fence=PREVIOUS) as fake:
        assert await install_key(fake.url, KEY, timeout=5) == 1
        assert fake.signing_setups[-1] == KEY and fake._mav.signing.secret_key == KEY
        async with open_vehicle(fake.url, 10, signing_key=KEY) as vehicle:
            await upload_fence(vehicle, NEW)
        # a vehicle that already signs takes a new key only from a message signed with the old
        with pytest.raises(SigningSetupError, match="sign with the key it holds"):
            await install_key(fake.url, OTHER, None, timeout=3)
        assert fake._mav.signing.secret_key == KEY
        await install_key(fake.url, OTHER, KEY, timeout=5)
        assert fake._mav.signing.secret_key == OTHER
        await install_key(fake.url, None, OTHER, timeout=5)  # off: all-zero key
        assert fake.signing_setups[-1] == bytes(32) and fake._mav.signing.secret_key is None


async def test_setup_reports_a_silent_link():
    url = f"udpin://127.0.0.1:{_free_port()}"
    with pytest.raises(SigningSetupError, match="no autopilot heartbeat"):
        await install_key(url, KEY, timeout=0.5)


def _free_port():
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
