"""MAVLink 2 signing on real ArduPilot SITL, through the ``alphafence`` command as an operator
runs it: ``signing keygen``, ``signing setup``, then ``upload`` with the right key, a wrong key
and no key, and ``download``.

The vehicle link is SITL's SERIAL1 (``radio=True``: ArduPilot's MAVLink channel 1, as a
telemetry radio or a companion's UDP link would be). Channel 0 (SERIAL0, "USB" on a flight
controller) is the one ArduPilot keeps accepting unsigned messages on once signing is on
(GCS_Signing.cpp ``accept_unsigned_callback``); the test checks that too, since it is what an
operator must know: signing protects the telemetry links, not a USB cable.

Measured (egham, speedup 5, 2-core machine): setup confirmed in ~1.1 s (the second heartbeat
comes signed with the new key); a signed upload of 5 items and read-back ~0.02 s after
connecting; a wrong key fails at discovery after --timeout (every vehicle message dropped
as signed with another key); no key: MAVSDK connects (it reads signed frames) but ArduPilot
drops every unsigned request, so the upload times out (~2.5 s) and the read-back of what the
vehicle holds fails the same way (~11 s more). The whole test takes about 40 s wall.
"""

from __future__ import annotations

import asyncio
import re
import signal
import sys
from importlib import resources

import pytest

from alphafence.fencefiles import qgc_plan as plan
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.mavlink.items import CIRCLE_EXCLUSION, POLYGON_EXCLUSION, FenceItem

pytestmark = pytest.mark.sitl

EGHAM = (-0.5520, 51.4300)  # lon, lat near the egham home
DEMO_SCENE = resources.files("alphafence") / "data" / "demo-scene.geojson"


def _fence(n_vertices, radius):
    lon, lat = EGHAM
    d = 0.001
    square = [
        (lon - d, lat + d),
        (lon + d, lat + d),
        (lon + d, lat + 2 * d),
        (lon - d, lat + 2 * d),
    ]
    items = [FenceItem(POLYGON_EXCLUSION, 4.0, x, y) for x, y in square[:n_vertices]]
    return items + [FenceItem(CIRCLE_EXCLUSION, radius, lon + 0.003, lat)]


def _spawn(args):
    """``alphafence ARGS`` as an operator runs it, in a child process."""
    return asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "alphafence",
        *map(str, args),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def alphafence(*args, timeout=60.0):
    proc = await _spawn(args)
    out, err = await asyncio.wait_for(proc.communicate(), timeout)
    return proc.returncode, out.decode(), err.decode()


async def monitor_checks(sitl, *args, heartbeats):
    """Run ``alphafence monitor`` until it is up (it prints the onboard fence it downloaded),
    then for ``heartbeats`` more of the vehicle's HEARTBEATs (1 Hz of its own time, watched on
    SERIAL0), stop it as systemd would (SIGTERM), and return the number of checks it reports."""
    proc = await _spawn(args)
    said = []
    try:
        await asyncio.wait_for(_until_line(proc.stdout, "onboard fence:", said), 60)
        await asyncio.wait_for(_heartbeats(sitl.connection_url, heartbeats), 60)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = await asyncio.wait_for(proc.communicate(), 20)
    out = "".join(said) + out.decode()
    assert proc.returncode == 0, err.decode()
    found = re.search(r"stopped after (\d+) checks", out)
    assert found, out
    return int(found.group(1))


async def _until_line(stream, text, said):
    """Read ``stream`` until a line holding ``text`` (every line read kept in ``said``)."""
    while line := (await stream.readline()).decode():
        said.append(line)
        if text in line:
            return
    raise AssertionError(f"ended without {text!r}: {''.join(said)}")


async def _heartbeats(url, n):
    """Wait for ``n`` HEARTBEATs of the autopilot at ``url``."""
    from alphafence.mavlink import ids
    from alphafence.vehicle.link import open_vehicle

    async with open_vehicle(url) as vehicle:
        sysid, seen = await vehicle.system_id(), 0
        async for m in vehicle.messages("HEARTBEAT"):
            ours = m.system_id == sysid and m.fields["autopilot"] != ids.MAV_AUTOPILOT_INVALID
            seen += ours
            if seen >= n:
                return


@pytest.mark.parametrize("sitl", [{"radio": True}], indirect=True)
async def test_signing_refuses_wrong_and_missing_keys(sitl, tmp_path):
    key, wrong = tmp_path / "vehicle.key", tmp_path / "wrong.key"
    first, second = tmp_path / "first.plan", tmp_path / "second.plan"
    first.write_text(plan.dumps(plan.plan_document(_fence(4, 30.0))))
    second.write_text(plan.dumps(plan.plan_document(_fence(3, 80.0))))
    for path in (key, wrong):
        assert (await alphafence("signing", "keygen", path))[0] == 0

    url = sitl.radio_url
    code, out, err = await alphafence("signing", "setup", "--connect", url, "--key", key)
    assert code == 0, err
    assert "now signs with key" in out and "confirmed" in out

    upload = ("upload", "--allow-unsigned", "--connect", url)
    code, out, err = await alphafence(*upload, first, "--signing-key", key)
    assert code == 0, err
    assert "read them back identical" in out

    code, out, err = await alphafence(*upload, second, "--signing-key", wrong, "--timeout", "4")
    assert code == 3
    assert "signed with another key" in err, err

    code, out, err = await alphafence(*upload, second, timeout=90)
    assert code == 3
    assert "stopped answering" in err and "give --signing-key" in err, err

    got = tmp_path / "got.plan"
    code, out, err = await alphafence("download", "--connect", url, "-o", got, "--signing-key", key)
    assert code == 0, err
    assert read_plan_fence(got) == read_plan_fence(first)  # the refused uploads changed nothing

    # channel 0 ("USB") still takes unsigned messages: ArduPilot's rule, not the kit's
    code, out, err = await alphafence(
        "download", "--connect", sitl.connection_url, "-o", tmp_path / "usb.plan"
    )
    assert code == 0, err
    assert read_plan_fence(tmp_path / "usb.plan") == read_plan_fence(first)

    # the monitor over the signed link: telemetry flows and is checked; a wrong key is refused
    fences = tmp_path / "fences.geojson"
    code, out, err = await alphafence("build", DEMO_SCENE, "-o", fences)
    assert code == 0, err
    monitor = ("monitor", "--allow-unsigned", "--connect", url, "--fences", fences)
    code, out, err = await alphafence(*monitor, "--signing-key", wrong, "--timeout", "4")
    assert code == 3 and "signed with another key" in err, err
    checks = await monitor_checks(sitl, *monitor, "--signing-key", key, heartbeats=5)
    assert checks >= 10  # positions at 10 Hz of the vehicle's time: 59 measured

    # switching signing off needs the current key; afterwards the plain link works again
    code, out, err = await alphafence("signing", "remove", "--connect", url, "--signing-key", key)
    assert code == 0, err
    code, out, err = await alphafence(*upload, second)
    assert code == 0, err
