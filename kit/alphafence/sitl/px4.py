"""Launch a headless PX4 SITL (its built-in SIH quadrotor, no Gazebo) from asyncio.

::

    async with launch_px4(home=(35.86, 14.45, 60.0)) as px4:
        ...  # PX4 is ready for takeoff with a GPS fix
        async with open_vehicle(px4.connection_url) as vehicle:
            ...

AlphaFence ships no PX4 code: the ``px4`` binary and its ``etc/`` (ROMFS) come from the user's
build (``make px4_sitl_default`` in PX4-Autopilot) or a packaged copy of one
(:func:`find_px4`). Each run gets a new directory holding the command links PX4's start
script calls (``px4-param``, ...; made here, so a copy whose links were flattened into files
still runs), its parameters, dataman and logs.

PX4's ports are fixed by its instance number N (0-9): it sends MAVLink for an offboard API to
``127.0.0.1:14540+N`` (:attr:`Px4Instance.connection_url`). Its start scripts are copied into
the run's directory with the ground-station link left out: every PX4 instance would otherwise
send to UDP 14550, where a ground station, or another test's vehicle, listens. Instance numbers
are reserved across processes (an exclusive lock file each, as for ArduPilot).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import tempfile
from pathlib import Path

from alphafence.errors import SitlError
from alphafence.sitl.ports import LOOPBACK, InstanceLock

PX4_NOT_FOUND_HELP = (
    "no PX4 SITL found: set PX4_SITL to PX4-Autopilot's build/px4_sitl_default (built with "
    "'make px4_sitl_default'), or to a directory holding its bin/px4 and etc/"
)
MAX_INSTANCE = 9  # PX4's ports are 14540 + N ...: it takes instances 0-9
API_PORT_BASE = 14540  # PX4 sends its onboard (API) MAVLink stream to 127.0.0.1:14540 + N
AIRFRAME = "10040"  # sihsim_quadx: SIH's quadrotor
READY = b"Ready for takeoff"  # commander's line once it has a fix and passes pre-arm checks
LOG_NAME = "px4.log"


def px4_candidates():
    """Where to look, in order: $PX4_SITL, ~/PX4-Autopilot/build/px4_sitl_default."""
    env = os.environ.get("PX4_SITL")
    if env:
        yield Path(env).expanduser()
    yield Path.home() / "PX4-Autopilot/build/px4_sitl_default"


def find_px4() -> Path | None:
    """The first directory of :func:`px4_candidates` holding an executable ``bin/px4`` and
    PX4's ``etc/init.d-posix/rcS``; None when there is none."""
    for root in px4_candidates():
        binary = root / "bin/px4"
        if (
            binary.is_file()
            and os.access(binary, os.X_OK)
            and (root / "etc/init.d-posix/rcS").is_file()
        ):
            return root
    return None


GCS_LINK = "# GCS link\n"  # px4-rc.mavlink: the block that starts the link to UDP 14550
NEXT_LINK = "# API/Offboard link\n"


def _start_scripts(root: Path, etc: Path) -> None:
    """PX4's ``etc/`` copied to ``etc``, its ground-station link (to 14550) left out."""
    import shutil

    shutil.copytree(root / "etc", etc)
    rc = etc / "init.d-posix/px4-rc.mavlink"
    rc.chmod(0o644)
    text = rc.read_text()
    if GCS_LINK in text and NEXT_LINK in text:
        a, b = text.index(GCS_LINK), text.index(NEXT_LINK)
        rc.write_text(
            text[:a] + "# (the GCS link to 14550: left out by AlphaFence's launcher)\n\n" + text[b:]
        )


def _command_links(root: Path, bin_dir: Path) -> None:
    """``bin_dir``: ``px4`` linked to the build's binary, and each of the build's ``px4-*``
    commands linked to ``px4`` (PX4 runs a command by the name it is called by)."""
    bin_dir.mkdir()
    (bin_dir / "px4").symlink_to((root / "bin/px4").resolve())
    for cmd in (root / "bin").glob("px4-*"):
        if cmd.name.endswith(".sh"):
            (bin_dir / cmd.name).symlink_to(cmd.resolve())
        else:
            (bin_dir / cmd.name).symlink_to("px4")


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the launching process dies (Linux), so a killed
    test run leaves no PX4 holding its ports (ArduPilot SITL does this itself)."""
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


class Px4Instance:
    """One PX4 SITL (SIH quadrotor) in its own temporary directory.

    Parameters
    ----------
    home : tuple, optional
        ``(lat, lon, alt_m)`` where the vehicle starts (default PX4's: Zurich).
    instance : int, optional
        0-9 (default: the lowest free one).
    params : dict, optional
        PX4 parameters set at start (``PX4_PARAM_<NAME>``).
    speed_factor : float
        SIH's speed-up (PX4_SIM_SPEED_FACTOR; 1 is real time).
    root : Path, optional
        The PX4 build (default :func:`find_px4`).
    """

    def __init__(self, home=None, instance=None, params=None, speed_factor=1.0, root=None):
        self.home = home
        self.params = dict(params or {})
        self.speed_factor = float(speed_factor)
        self.root = Path(root) if root is not None else find_px4()
        if self.root is None:
            raise SitlError(PX4_NOT_FOUND_HELP)
        self._wanted = instance
        self.instance = None
        self.proc = None
        self.dir = None
        self._lock = None
        self._ready = None
        self.log_lines: list[str] = []

    @property
    def connection_url(self) -> str:
        """Where PX4 sends its API stream: ``udpin:127.0.0.1:14540+N``."""
        return f"udpin:{LOOPBACK}:{API_PORT_BASE + self.instance}"

    def _reserve(self) -> None:
        wanted = range(MAX_INSTANCE + 1) if self._wanted is None else [self._wanted]
        for i in wanted:
            lock = InstanceLock.try_acquire(f"px4-{i}")
            if lock is not None:
                self._lock, self.instance = lock, i
                return
        raise SitlError(f"no free PX4 SITL instance in {list(wanted)}")

    def _env(self) -> dict:
        env = dict(os.environ)
        env.update(PX4_SIMULATOR="sihsim", PX4_SIM_MODEL="sihsim_quadx")
        env.update(PX4_SYS_AUTOSTART=AIRFRAME, PX4_SIM_SPEED_FACTOR=f"{self.speed_factor:g}")
        values = {"SDLOG_MODE": -1, **self.params}  # no ULog unless asked for
        if self.home is not None:
            lat, lon, alt = self.home
            values.update(SIH_LOC_LAT0=lat, SIH_LOC_LON0=lon, SIH_LOC_H0=alt)
        env.update({f"PX4_PARAM_{k}": f"{v:g}" if isinstance(v, float) else str(v)
                    for k, v in values.items()})  # fmt: skip
        return env

    async def start(self) -> Px4Instance:
        """Start PX4 (without waiting for readiness: :meth:`wait_ready`)."""
        self._reserve()
        self.dir = Path(tempfile.mkdtemp(prefix=f"alphafence-px4-{self.instance}-"))
        _command_links(self.root, self.dir / "bin")
        _start_scripts(self.root, self.dir / "etc")
        work = self.dir / "work"
        work.mkdir()
        self._ready = asyncio.get_running_loop().create_future()
        self.proc = await asyncio.create_subprocess_exec(
            str(self.dir / "bin/px4"), "-d", "-i", str(self.instance), "-w", str(work),
            str(self.dir / "etc"), cwd=work, env=self._env(), stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
            start_new_session=True, preexec_fn=_die_with_parent,
        )  # fmt: skip
        self._reader = asyncio.create_task(self._read_log())
        return self

    async def _read_log(self) -> None:
        with open(self.dir / LOG_NAME, "wb") as log:
            while line := await self.proc.stdout.readline():
                log.write(line)
                log.flush()
                self.log_lines.append(line.decode("utf-8", "replace").rstrip())
                if READY in line and not self._ready.done():
                    self._ready.set_result(True)
        if not self._ready.done():
            self._ready.set_exception(SitlError(self._exit_message()))

    def _exit_message(self) -> str:
        tail = " | ".join(self.log_lines[-5:])
        return f"PX4 SITL (instance {self.instance}) exited before it was ready: {tail}"

    async def wait_ready(self, timeout: float = 120.0) -> None:
        """Wait until PX4 reports "Ready for takeoff" (it has a fix and passes its checks).

        Raises
        ------
        SitlError
            PX4 exited, or did not get ready within ``timeout``.
        """
        try:
            await asyncio.wait_for(asyncio.shield(self._ready), timeout)
        except asyncio.TimeoutError:
            raise SitlError(
                f"PX4 SITL (instance {self.instance}) not ready within {timeout:g} s; "
                f"see {self.dir / LOG_NAME}"
            ) from None

    async def shell(self, command: str, *args: str) -> str:
        """Run one of PX4's own shell commands on this instance (``param``, ``listener``...)
        and return what it prints: PX4's word, owing nothing to MAVLink."""
        proc = await asyncio.create_subprocess_exec(
            str(self.dir / "bin" / f"px4-{command}"), "--instance", str(self.instance), *args,
            cwd=self.dir / "work", stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
        )  # fmt: skip
        out, _ = await proc.communicate()
        return out.decode("utf-8", "replace")

    async def param(self, name: str) -> str:
        """A parameter's value as PX4's ``param show`` prints it (None when it has none)."""
        for line in (await self.shell("param", "show", name)).splitlines():
            if f" {name} [" in line and ":" in line:
                return line.rsplit(":", 1)[1].strip()
        return None

    def ulogs(self) -> list:
        """The flight logs PX4 has written (``.ulg``; logging is on with ``SDLOG_MODE`` 0 in
        ``params``: from arming to disarming), oldest first."""
        return sorted((self.dir / "work").glob("log/*/*.ulg"))

    def logged(self, text: str) -> list:
        """The lines of PX4's console log holding ``text``."""
        return [line for line in self.log_lines if text in line]

    async def stop(self, timeout: float = 10.0) -> None:
        """SIGTERM to PX4's process group, SIGKILL after ``timeout``; its directory removed."""
        import shutil

        if self.proc is not None and self.proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                await asyncio.wait_for(self.proc.wait(), timeout)
            except asyncio.TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                await self.proc.wait()
        if getattr(self, "_reader", None) is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._reader, timeout)
        if self.dir is not None and not os.environ.get("ALPHAFENCE_KEEP_PX4"):
            shutil.rmtree(self.dir, ignore_errors=True)
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    async def __aenter__(self) -> Px4Instance:
        return await self.start()

    async def __aexit__(self, *exc) -> None:
        await self.stop()


@contextlib.asynccontextmanager
async def launch_px4(home=None, timeout: float = 120.0, **kwargs):
    """``async with launch_px4(home=(lat, lon, alt)) as px4``: a PX4 SITL ready for takeoff.
    Keyword arguments go to :class:`Px4Instance`."""
    px4 = Px4Instance(home=home, **kwargs)
    async with px4:
        await px4.wait_ready(timeout)
        yield px4
