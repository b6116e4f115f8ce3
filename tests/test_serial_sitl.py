"""The kit over a serial port to real ArduPilot SITL, as an operator connects over USB or a
telemetry radio: SITL's SERIAL1 (MAVLink 2, ArduPilot's channel 1, where signing is enforced)
on one end of a socat pseudo-terminal pair (``--serial1 uart:DIR/a:57600``), the kit on the
other as the serial device ``DIR/b,57600``. Through the ``alphafence`` command: upload,
download and monitor, unsigned; then ``signing setup`` over the port, and the same signed (a
wrong key refused). On each vehicle link (the ``link`` fixture; ``signing setup`` is the kit's
own on both; MAVSDK opens the port itself, or through the kit's bridge when signing). SITL's SERIAL0 stays on loopback UDP, where readiness and the
monitor's heartbeat count are watched.

Skipped with one line without socat (Debian: apt-get install socat) or an arducopter binary.
"""

from __future__ import annotations

import pytest

from alphafence.fencefiles import qgc_plan as plan
from alphafence.fencefiles.qgc_plan import read_plan_fence
from tests.serial_fixtures import NO_SOCAT, SOCAT, socat_pair
from tests.test_signing_sitl import DEMO_SCENE, _fence, alphafence, monitor_checks

pytestmark = [pytest.mark.sitl, pytest.mark.usefixtures("link")]  # pymavlink, then MAVSDK


@pytest.fixture
async def serial_sitl(sitl_factory, tmp_path):
    """(SITL with SERIAL1 on a pty, the kit's end of the pair as ``PATH,57600``)."""
    if SOCAT is None:
        pytest.skip(NO_SOCAT)
    async with socat_pair(str(tmp_path)) as (a, b):
        sitl = await sitl_factory(serial1=f"uart:{a}:57600")
        yield sitl, f"{b},57600"
        await sitl.stop()  # before its port goes away with socat


async def test_upload_download_and_monitor_over_a_serial_port(serial_sitl, tmp_path):
    sitl, port = serial_sitl
    first, second = tmp_path / "first.plan", tmp_path / "second.plan"
    first.write_text(plan.dumps(plan.plan_document(_fence(4, 30.0))))
    second.write_text(plan.dumps(plan.plan_document(_fence(3, 80.0))))
    fences = tmp_path / "fences.geojson"
    assert (await alphafence("build", DEMO_SCENE, "-o", fences))[0] == 0
    upload = ("upload", "--allow-unsigned", "--connect", port)
    monitor = ("monitor", "--allow-unsigned", "--connect", port, "--fences", fences)

    # unsigned
    code, out, err = await alphafence(*upload, first)
    assert code == 0, err
    assert "read them back identical" in out
    got = tmp_path / "got.plan"
    code, out, err = await alphafence("download", "--connect", port, "-o", got)
    assert code == 0, err
    assert read_plan_fence(got) == read_plan_fence(first)
    assert await monitor_checks(sitl, *monitor, heartbeats=5) >= 10

    # signed: the key installed over the port, then only messages signed with it count
    key, wrong = tmp_path / "vehicle.key", tmp_path / "wrong.key"
    for path in (key, wrong):
        assert (await alphafence("signing", "keygen", path))[0] == 0
    code, out, err = await alphafence("signing", "setup", "--connect", port, "--key", key)
    assert code == 0, err
    assert "now signs with key" in out and "confirmed" in out
    code, out, err = await alphafence(*upload, second, "--signing-key", key)
    assert code == 0, err
    assert "read them back identical" in out
    code, out, err = await alphafence(*upload, first, "--signing-key", wrong, "--timeout", "4")
    assert code == 3 and "signed with another key" in err, err
    code, out, err = await alphafence(
        "download", "--connect", port, "-o", got, "--signing-key", key
    )
    assert code == 0, err
    assert read_plan_fence(got) == read_plan_fence(second)  # the wrong key changed nothing
    assert await monitor_checks(sitl, *monitor, "--signing-key", key, heartbeats=5) >= 10
