"""The SITL harness: homes, parameter files and the SITL command line (no binary needed); the
launcher's life cycle against stand-in processes and a fake vehicle; and, marked ``sitl``, a real
ArduPilot copter SITL: readiness, two instances at once, clean shutdown, early exit."""

import asyncio
import math
import os
import re
import socket
import stat
import sys
import time
from pathlib import Path

import pytest

from alphafence.cli import main
from alphafence.errors import InputError, SitlError
from alphafence.sitl.cmdline import defaults_files, sitl_command, write_param_file
from alphafence.sitl.find import COPTER_DEFAULTS
from alphafence.sitl.homes import Home, kit_parm_path, load_homes, parse_homes, resolve_home
from alphafence.sitl.instance import SitlInstance
from alphafence.sitl.ports import RCIN_BASE_PORT, reserve_instance
from alphafence.sitl.readiness import ReadyState

from .helpers import until

ROOT = Path(__file__).resolve().parents[1]


# --- homes ------------------------------------------------------------------------------------


def test_kit_homes():
    homes = load_homes()
    assert {"egham", "malta_airport"} <= set(homes)
    egham = homes["egham"]
    assert (egham.lat, egham.lon, egham.alt, egham.heading) == (51.43, -0.55, 20.0, 0.0)
    assert egham.arg() == "51.43,-0.55,20,0"
    malta = homes["malta_airport"]
    # just outside Malta International (aerodrome reference point 35.8575, 14.4775)
    assert 0.005 < math.dist((malta.lat, malta.lon), (35.8575, 14.4775)) < 0.02
    for home in homes.values():
        assert home.description


def test_parse_homes_errors():
    good = "[here]\nlat = 1.5\nlon = -2\nalt = 3\n"
    assert parse_homes(good)["here"] == Home("here", 1.5, -2.0, 3.0, 0.0, "")
    bad = {
        "[here]\nlon = 1\nalt = 3\n": "missing lat",
        "[here]\nlat = 91\nlon = 1\nalt = 3\n": "lat 91 is outside",
        "[here]\nlat = 1\nlon = 1\nalt = 3\nheading = 360\n": "heading 360",
        "[here]\nlat = '1'\nlon = 1\nalt = 3\n": "lat must be a finite number",
        "[here]\nlat = 1\nlon = 1\nalt = 3\nyaw = 2\n": "unknown keys ['yaw']",
        "[Here]\nlat = 1\nlon = 1\nalt = 3\n": "names are lower case",
        "here = 1\n": "must be a table",
        "[here\n": "not valid TOML",
        "": "no homes",
    }
    for text, message in bad.items():
        with pytest.raises(InputError, match=re.escape(message)) as info:
            parse_homes(text, "h.toml")
        assert str(info.value).startswith("h.toml")


def test_resolve_home():
    assert resolve_home("egham").name == "egham"
    custom = resolve_home("35.9,14.4,50,90")
    assert (custom.lat, custom.lon, custom.alt, custom.heading) == (35.9, 14.4, 50.0, 90.0)
    assert resolve_home("35.9,14.4,50").heading == 0.0
    with pytest.raises(InputError, match="egham, malta_airport"):
        resolve_home("nowhere")
    with pytest.raises(InputError, match="lat 95"):
        resolve_home("95,1,1,0")


# --- parameter files and the command line -------------------------------------------------


def _parm_lines(path):
    for line in Path(path).read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, value = line.split()
            yield name, float(value)


def test_kit_parm_file_is_short_and_well_formed():
    values = dict(_parm_lines(kit_parm_path()))
    assert 0 < len(values) <= 20
    assert all(re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", name) for name in values)
    assert values["FENCE_ENABLE"] == 0 and values["FRAME_CLASS"] == 1


def test_repo_sitl_directory_is_the_package_data():
    for name in ("homes.toml", "alphafence-test.parm"):
        assert (ROOT / "sitl" / name).read_bytes() == (
            ROOT / "kit/alphafence/data/sitl" / name
        ).read_bytes()
    assert "kit/alphafence/data/sitl" in (ROOT / "sitl/README.md").read_text()
    assert '"data/sitl/*"' in (ROOT / "pyproject.toml").read_text()


def test_write_param_file(tmp_path):
    path = write_param_file(tmp_path / "p.parm", {"FENCE_ENABLE": 1, "FENCE_RADIUS": 75.5})
    assert dict(_parm_lines(path)) == {"FENCE_ENABLE": 1.0, "FENCE_RADIUS": 75.5}
    with pytest.raises(SitlError, match="parameter name"):
        write_param_file(tmp_path / "q.parm", {"fence_enable": 1})
    with pytest.raises(SitlError, match="finite number"):
        write_param_file(tmp_path / "q.parm", {"FENCE_RADIUS": math.nan})


def _exe(path, text="#!/bin/sh\n"):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def test_defaults_files_use_the_tree_the_binary_was_built_in(tmp_path):
    tree = tmp_path / "ardupilot"
    binary = _exe(tree / "build/sitl/bin/arducopter")
    (tree / COPTER_DEFAULTS).parent.mkdir(parents=True)
    (tree / COPTER_DEFAULTS).write_text("FRAME_CLASS 1\n")
    extra = tmp_path / "mine.parm"
    assert defaults_files(binary, [extra]) == [tree / COPTER_DEFAULTS, kit_parm_path(), extra]
    lone = _exe(tmp_path / "elsewhere/arducopter")
    assert defaults_files(lone) == [kit_parm_path()]


def test_sitl_command():
    home = Home("egham", 51.43, -0.55, 20.0, 0.0)
    argv = sitl_command(
        "/x/arducopter", home, port=40123, instance=3, speedup=5, defaults=["/a.parm", "/b.parm"]
    )
    opts = dict(zip(argv[1::2], argv[2::2]))
    assert argv[0] == "/x/arducopter"
    assert opts == {
        "--model": "+",
        "--home": "51.43,-0.55,20,0",
        "--speedup": "5",
        "-I": "3",
        "--defaults": "/a.parm,/b.parm",
        "--serial0": "udpclient:127.0.0.1:40123",
        "--serial1": "none",
        "--serial2": "none",
    }
    assert not any("0.0.0.0" in a or a.startswith("tcp") for a in argv)
    with pytest.raises(SitlError, match="comma"):
        sitl_command("/x/arducopter", home, port=1, defaults=["/a,b.parm"])
    with pytest.raises(SitlError, match="speedup"):
        sitl_command("/x/arducopter", home, port=1, speedup=0)


def test_instance_numbers_are_reserved():
    a = reserve_instance()
    b = reserve_instance()
    try:
        assert a.instance != b.instance
        with pytest.raises(SitlError, match="in use"):
            reserve_instance(a.instance)
    finally:
        a.release()
        b.release()
    again = reserve_instance(a.instance)
    again.release()


def test_readiness_needs_every_condition():
    state = ReadyState(
        system=(1, 1), gps_fix=6, ekf_flags=0x33F, position=(1, 2, 3), home=(1, 2, 3)
    )
    assert state.ready
    for change in (
        {"system": None},
        {"gps_fix": 2},
        {"ekf_flags": 0xA7},  # constant-position mode, no absolute position: not ready
        {"ekf_flags": None},
        {"position": None},
        {"home": None},
    ):
        assert not ReadyState(**{**state.__dict__, **change}).ready
    assert "no absolute horizontal position" in ReadyState(ekf_flags=0xA7).describe()


# --- the CLI ------------------------------------------------------------------------------------


def test_cli_lists_homes(capsys):
    assert main(["sitl", "--list-homes"]) == 0
    out = capsys.readouterr().out
    assert "egham" in out and "51.43,-0.55,20,0" in out and "malta_airport" in out


def test_cli_unknown_home(capsys):
    assert main(["sitl", "--home", "atlantis"]) == 2
    assert "unknown home 'atlantis'" in capsys.readouterr().err


# --- the launcher against stand-in processes (no SITL needed) -------------------------------


def _pid_gone(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


async def test_stop_terminates_and_cleans_up(tmp_path):
    fake = _exe(tmp_path / "arducopter", '#!/bin/sh\necho started "$@"\nexec sleep 60\n')
    sitl = SitlInstance("egham", binary=fake, speedup=3)
    async with sitl:
        assert sitl.running and sitl.workdir.is_dir()
        assert sitl.connection_url == f"udpin://127.0.0.1:{sitl.port}"
        assert sitl.pymavlink_url == f"udpin:127.0.0.1:{sitl.port}"
        await until(lambda: "started" in sitl.log_tail(), "the stand-in started")
        assert f"--serial0 udpclient:127.0.0.1:{sitl.port}" in sitl.log_tail()
        pid, workdir, instance = sitl.pid, sitl.workdir, sitl.instance
    assert sitl.process.returncode == -15
    assert _pid_gone(pid) and not workdir.exists()
    reserve_instance(instance).release()  # the instance number is free again


async def test_stop_kills_what_ignores_sigterm(tmp_path):
    script = "#!/bin/sh\ntrap '' TERM\necho ignoring TERM\nwhile :; do sleep 0.05; done\n"
    sitl = await SitlInstance("egham", binary=_exe(tmp_path / "arducopter", script)).start()
    await until(lambda: "ignoring TERM" in sitl.log_tail(), "the TERM trap set")
    # it never exits on TERM: only the SIGKILL after the 0.5 s ends it (a wait for an exit
    # would hang until the deadline)
    assert await asyncio.wait_for(sitl.stop(timeout=0.5), 60) == -9
    assert _pid_gone(sitl.pid) and not sitl.workdir.exists()


async def test_early_exit_reports_the_log_tail(tmp_path):
    fake = _exe(tmp_path / "arducopter", "#!/bin/sh\necho 'Vehicle model (x) not found'\nexit 3\n")
    async with SitlInstance("egham", binary=fake) as sitl:
        with pytest.raises(SitlError, match=r"exited with code 3[\s\S]*Vehicle model \(x\)"):
            await sitl.wait_ready(10)


async def test_ready_timeout_says_what_is_missing(tmp_path):
    fake = _exe(tmp_path / "arducopter", "#!/bin/sh\nexec sleep 60\n")
    async with SitlInstance("egham", binary=fake) as sitl:
        with pytest.raises(SitlError, match="not ready after 0.3 s: no heartbeat"):
            await sitl.wait_ready(0.3)
        # the readiness listener let go of the port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", sitl.port))


class FrozenClock:
    """A module's ``time`` whose monotonic clock stands still (the rest is the time module)."""

    def __init__(self):
        self.now = time.monotonic()

    def monotonic(self):
        return self.now

    def __getattr__(self, name):
        return getattr(time, name)


async def test_readiness_from_a_fake_vehicle(tmp_path, monkeypatch):
    """wait_ready parses the vehicle's messages, asks it for the ones it needs, and returns
    once all conditions hold, with the port free again. Its clock stands still here, so it
    re-asks nothing ("then once a second" never comes) and its own timeout never fires: it is
    ready only if it asked at the first heartbeat and one round of asks was enough."""
    from pymavlink.dialects.v20 import ardupilotmega as mav2

    import alphafence.sitl.instance

    monkeypatch.setattr(alphafence.sitl.instance, "time", FrozenClock())
    fake = _exe(tmp_path / "arducopter", "#!/bin/sh\nexec sleep 60\n")
    async with SitlInstance("egham", binary=fake) as sitl:
        vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        vehicle.bind(("127.0.0.1", 0))
        vehicle.setblocking(False)
        mav = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
        asked = []

        lat, lon, alt = 514300000, -5500000, 20000
        streams = {  # like SITL, the fake sends only the heartbeat until asked for more
            24: mav.gps_raw_int_encode(0, 3, lat, lon, alt, 0, 0, 0, 0, 10),
            33: mav.global_position_int_encode(0, lat, lon, alt, 0, 0, 0, 0, 0),
            193: mav.ekf_status_report_encode(0x33F, 0, 0, 0, 0, 0),
        }
        home = mav.home_position_encode(lat, lon, alt, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0)

        async def fly():
            while True:
                msgs = [mav.heartbeat_encode(2, 3, 0, 0, 3)]  # a quadrotor, ArduPilot
                msgs += [streams[int(m.param1)] for m in asked if m.command == 511]
                for msg in msgs:
                    vehicle.sendto(msg.pack(mav), ("127.0.0.1", sitl.port))
                try:
                    while True:
                        for m in mav.parse_buffer(vehicle.recv(1024)) or []:
                            if m.get_type() == "COMMAND_LONG":
                                asked.append(m)
                                if m.command == 512 and int(m.param1) == 242:
                                    vehicle.sendto(home.pack(mav), ("127.0.0.1", sitl.port))
                except BlockingIOError:
                    pass
                await asyncio.sleep(0.05)

        flying = asyncio.create_task(fly())
        try:  # the deadline only stops a hang (the frozen clock keeps wait_ready's from firing)
            state = await asyncio.wait_for(sitl.wait_ready(10), 60)
        finally:
            flying.cancel()
            vehicle.close()
        assert state.ready and state.home == pytest.approx((51.43, -0.55, 20.0))
        # each asked for once (intervals above 0; 0 is the reset to the default rates after)
        streams = sorted(int(m.param1) for m in asked if m.command == 511 and m.param2 > 0)
        assert streams == [24, 33, 193]
        assert [int(m.param1) for m in asked if m.command == 512] == [242]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", sitl.port))


# --- a real ArduPilot SITL ----------------------------------------------------------------------


def _sockets(pid):
    """(protocol, local address, local port, remote port) of every socket ``pid`` holds."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            m = re.fullmatch(r"socket:\[(\d+)\]", os.readlink(f"/proc/{pid}/fd/{fd}"))
        except OSError:
            continue
        if m:
            inodes.add(m.group(1))
    found = []
    for proto in ("tcp", "udp", "tcp6", "udp6"):
        with open(f"/proc/net/{proto}") as f:
            next(f)
            for line in f:
                cols = line.split()
                if cols[9] in inodes:
                    addr, port = cols[1].split(":")
                    found.append((proto, addr, int(port, 16), int(cols[2].split(":")[1], 16)))
    return found


def _near(position, home, tol=1e-4):
    return abs(position[0] - home.lat) < tol and abs(position[1] - home.lon) < tol


@pytest.mark.sitl
async def test_ready_at_speedup_1_then_mavsdk_connects(sitl_binary):
    """At real time the EKF has an absolute position about 40 s after boot; the readiness
    listener then hands the port over to MAVSDK."""
    import mavsdk.asyncio as ms
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    async with SitlInstance("egham", speedup=1, binary=sitl_binary) as sitl:
        state = await sitl.wait_ready(90)  # raises unless ready (EKF position, fix, home) by then
        assert _near(state.home, sitl.home) and _near(state.position, sitl.home)
        config = ms.Configuration.create_with_component_type(ms.ComponentType.GROUND_STATION)
        async with ms.Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(sitl.connection_url)
            system = await mavsdk.first_autopilot(timeout_s=10)
            assert system is not None
            telemetry = TelemetryAsync(system)
            await telemetry.set_rate_position(5)  # MAVSDK asks for no position stream itself

            async def first_fix():
                async for p in telemetry.subscribe_position():
                    if p.latitude_deg and not math.isnan(p.latitude_deg):
                        return p

            p = await asyncio.wait_for(first_fix(), 10)
            assert _near((p.latitude_deg, p.longitude_deg), sitl.home)


@pytest.mark.sitl
async def test_two_instances_at_once_then_shutdown(sitl_factory):
    a, b = await asyncio.gather(
        sitl_factory(home="egham", speedup=10, ready_timeout=45),
        sitl_factory(home="malta_airport", speedup=10, ready_timeout=45),
    )
    assert a.instance != b.instance and a.port != b.port and a.workdir != b.workdir
    # each listener heard its own vehicle
    assert _near(a.state.home, a.home) and _near(b.state.home, b.home)
    for sitl in (a, b):
        if not Path("/proc/net/udp").is_file():
            break
        socks = _sockets(sitl.pid)
        assert not [s for s in socks if s[0].startswith("tcp")], socks  # no TCP listeners
        for _proto, addr, port, _remote in socks:
            # loopback only, except ArduPilot's RC-input port (no option to change it)
            assert addr == "0100007F" or port == RCIN_BASE_PORT + 10 * sitl.instance, socks
        assert ("udp", "0100007F", sitl.port) in [(p, ad, r) for p, ad, _, r in socks]
    pid, workdir = a.pid, a.workdir
    await a.stop()
    assert _pid_gone(pid) and not workdir.exists()
    assert b.running and b.workdir.is_dir()


@pytest.mark.sitl
@pytest.mark.parametrize("sitl", [{"home": "monaco", "speedup": 10}], indirect=True)
async def test_fixture_yields_a_ready_instance(sitl):
    assert sitl.running and sitl.state.ready
    assert _near(sitl.state.position, load_homes()["monaco"])


@pytest.mark.sitl
async def test_sitl_exiting_early_is_reported(sitl_binary):
    async with SitlInstance("egham", binary=sitl_binary, model="no-such-model") as sitl:
        with pytest.raises(SitlError, match=r"exited with code \d+[\s\S]*no-such-model"):
            await sitl.wait_ready(20)


@pytest.mark.sitl
def test_cli_runs_sitl_until_interrupted(sitl_binary):
    """``alphafence sitl --home`` prints the connection URLs and stops SITL on Ctrl-C."""
    import signal
    import subprocess

    proc = subprocess.Popen(
        [sys.executable, "-m", "alphafence", "sitl", "--home", "egham", "--speedup", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    lines = []
    try:
        deadline = time.monotonic() + 45
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if line.startswith("Ctrl-C"):
                break
        out = "".join(lines)
        assert "ready: position 51.43" in out, out
        assert re.search(r"MAVSDK: +udpin://127\.0\.0\.1:\d+", out)
        pid = int(re.search(r"pid (\d+)", out).group(1))
        workdir = Path(re.search(r"working directory (\S+)", out).group(1))
        proc.send_signal(signal.SIGINT)
        assert proc.wait(15) == 0
        assert _pid_gone(pid) and not workdir.exists()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
