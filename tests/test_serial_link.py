"""Serial ports and TCP listening on each vehicle link, without SITL: the scripted ArduPilot
peer (tests/fake_vehicle.py) on one end of a socat pseudo-terminal pair, the kit on the other
as a serial device; the same peer connecting to the kit's ``tcpin`` port; the operator's
one-line errors; MAVSDK's log lines kept off the terminal as raw colour codes.

The same over a pty pair with real ArduPilot SITL on the other end is
tests/test_serial_sitl.py."""

from __future__ import annotations

import asyncio
import errno
import socket
import subprocess
import sys

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.fencefiles import qgc_plan as plan
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.vehicle.bridge import BridgeError, VehicleLink
from alphafence.vehicle.fence_transfer import download_fence, same_items, upload_fence
from alphafence.vehicle.link import LinkError, open_vehicle
from alphafence.vehicle.transports import serial_error
from tests import serial_fixtures
from tests.serial_fixtures import PtyFake, TcpFake
from tests.test_signing import KEY, OTHER
from tests.test_upload_faults import NEW, PREVIOUS

pty_pair = serial_fixtures.pty_pair  # the fixture


def signed_with(key: bytes, frame: bytes) -> bool:
    """Whether ``frame`` (one frame's bytes) carries a good signature made with ``key``."""
    codec = mav.MAVLink(None)
    codec.signing.secret_key = key
    codec.robust_parsing = True
    return any(m.get_type() != "BAD_DATA" for m in codec.parse_buffer(frame) or [])


def _lats(items):
    return [round(it.lat, 7) for it in items]


async def test_upload_and_download_over_a_serial_port(link, pty_pair):
    a, b = pty_pair
    async with PtyFake(a, fence=PREVIOUS) as fake:
        async with open_vehicle(f"{b},57600", timeout=10) as vehicle:
            report = await upload_fence(vehicle, NEW)
            assert report.verified
            assert same_items(NEW, await download_fence(vehicle)) == []
    assert _lats(fake.fence) == _lats(NEW) and fake.fence_writes == 1


async def test_signed_over_a_serial_port(link, pty_pair):
    a, b = pty_pair
    async with PtyFake(a, fence=PREVIOUS, signing_key=KEY) as fake:
        with pytest.raises(LinkError, match="signed with another key"):
            async with open_vehicle(f"serial://{b}:57600", 3, signing_key=OTHER):
                pass
        assert fake.fence_writes == 0
        async with open_vehicle(f"serial://{b}:57600", 10, signing_key=KEY) as vehicle:
            await upload_fence(vehicle, NEW)
            stats = vehicle.link_stats()
    assert _lats(fake.fence) == _lats(NEW)
    assert fake._mav.signing.goodsig_count > 0  # the fake checked our signatures
    # the wrong key's frames were refused (some may reach the fake after the first link
    # closed, still in the pty); nothing signed with the right key was
    assert any(signed_with(OTHER, frame) for frame in fake.rejected)
    assert not any(signed_with(KEY, frame) for frame in fake.rejected)
    assert stats.received > 0 and stats.unsigned == stats.bad_signature == 0


async def test_cli_download_over_a_serial_port(pty_pair, tmp_path):
    """``alphafence download --connect /dev/...`` as typed, the default link."""
    a, b = pty_pair
    out = tmp_path / "got.plan"
    async with PtyFake(a, fence=NEW):
        argv = ["download", "--connect", b, "-o", str(out), "--link", "pymavlink"]
        assert await asyncio.to_thread(main, argv) == 0
    sent = tmp_path / "sent.plan"
    sent.write_text(plan.dumps(plan.plan_document(NEW)))
    assert read_plan_fence(out) == read_plan_fence(sent)


async def test_a_port_in_use_is_busy(pty_pair):
    _, b = pty_pair
    first = await VehicleLink(b).open()
    try:
        with pytest.raises(BridgeError, match=rf"^{b}: busy: another program has the port open"):
            await VehicleLink(f"{b},57600").open()
    finally:
        await first.close()
    again = await VehicleLink(b).open()  # closed: free again
    await again.close()


async def test_a_missing_port_is_one_line(link, tmp_path):
    missing = tmp_path / "ttyACM9"
    with pytest.raises(LinkError) as err:
        async with open_vehicle(str(missing), timeout=1):
            pass
    assert str(err.value) == (
        f"{missing}: no such serial port (is the vehicle plugged in? ls /dev/serial/by-id/)"
    )


@pytest.mark.parametrize(
    "code, says",
    [
        (errno.EACCES, "permission denied: add your user to the dialout group"),
        (errno.EBUSY, "busy: another program has the port open"),
        (errno.ENOENT, "no such serial port"),
        (errno.EIO, "cannot open the serial port"),
    ],
)
def test_serial_errors_name_the_port_and_what_to_do(code, says):
    # as root (CI) no port is refused for permissions: the system's error is made here
    line = str(serial_error("/dev/ttyACM0", 115200, OSError(code, "as the system says")))
    assert line.startswith("/dev/ttyACM0: ") and says in line and "\n" not in line


async def test_tcpin_accepts_the_vehicle(link):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"tcpin:127.0.0.1:{port}"
    fake = TcpFake(port, fence=PREVIOUS, signing_key=KEY)

    async def vehicle_connects():
        while True:  # the kit listens once open_vehicle has started
            try:
                return await fake.start()
            except ConnectionRefusedError:
                await asyncio.sleep(0.05)

    task = asyncio.create_task(vehicle_connects())
    try:
        async with open_vehicle(url, 10, signing_key=KEY) as vehicle:
            await task
            await upload_fence(vehicle, NEW)
    finally:
        await task
        await fake.stop()
    assert _lats(fake.fence) == _lats(NEW) and fake._mav.signing.goodsig_count > 0


async def test_udpbcast_learns_the_vehicle_from_its_answer():
    """``udpbcast``: the kit sends to the address given until the vehicle answers, then to the
    vehicle (a loopback address stands for the broadcast one here)."""
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.setblocking(False)
    loop = asyncio.get_running_loop()
    codec = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    beat = codec.heartbeat_encode(
        mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, mav.MAV_STATE_STANDBY
    )

    async def answer():
        data, addr = await loop.sock_recvfrom(vehicle, 4096)  # the kit's first heartbeat
        for _ in range(3):
            await loop.sock_sendto(vehicle, beat.pack(codec), addr)
        return addr

    task = asyncio.create_task(answer())
    try:
        url = f"udpbcast:127.0.0.1:{vehicle.getsockname()[1]}"
        async with open_vehicle(url, timeout=5, link="pymavlink") as kit:
            assert await kit.system_id() == 1
            assert kit.link.remote == kit.link._wire.peer  # answering to the vehicle itself
            assert (await task)[1] == kit.link._wire.sockname[1]
    finally:
        task.cancel()
        vehicle.close()


def test_mavsdk_log_lines_reach_the_terminal_without_colour_codes(tmp_path):
    """MAVSDK's own error (it cannot set a non-terminal up as a serial port) comes as one
    plain ``mavsdk:`` line on stderr, not ``ESC[31m[..|Error] ESC[0m...``."""
    pytest.importorskip("mavsdk.asyncio")
    proc = subprocess.run(
        [sys.executable, "-m", "alphafence", "download", "--link", "mavsdk",
         "--connect", "serial:///dev/null:57600", "-o", str(tmp_path / "x.plan")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 3, proc.stderr
    assert "\x1b" not in proc.stderr + proc.stdout
    assert "mavsdk: Call open failed: Inappropriate ioctl for device" in proc.stderr
    assert "MAVSDK version" not in proc.stderr  # its info lines stay off the terminal
    assert "alphafence download: error: serial:///dev/null:57600: cannot open" in proc.stderr


@pytest.mark.parametrize(
    "port, warned", [("/dev/ttyUSB97", True), ("/dev/ttyAMA97", True), ("/dev/ttyACM97", False)]
)
def test_signing_setup_warns_before_sending_the_key_over_a_radio(tmp_path, capsys, port, warned):
    key = tmp_path / "k"
    assert main(["signing", "keygen", str(key)]) == 0
    code = main(["signing", "setup", "--connect", port, "--key", str(key), "--timeout", "1"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 3 and f"{port}: no such serial port" in err  # no such port on this machine
    said = f"SETUP_SIGNING carries the key in clear to {port}: if it is a telemetry radio"
    assert (said in err) == warned


async def test_a_port_that_goes_away_is_said(tmp_path):
    """The cable pulled (socat gone: the pty's other side closed): the link says so."""
    if serial_fixtures.SOCAT is None:
        pytest.skip(serial_fixtures.NO_SOCAT)
    async with serial_fixtures.socat_pair(str(tmp_path)) as (_, b):
        link = await VehicleLink(b).open()
    try:
        await asyncio.wait_for(link._stream.ended.wait(), 10)
        assert link.closed.startswith(f"the serial port {b} went away")
        assert link.stats.diagnosis(key_given=False) == "" and not link._stream.write(b"x")
    finally:
        await link.close()
