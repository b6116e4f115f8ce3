"""Launch ArduPilot copter SITL instances, one per fresh temporary directory, from asyncio.

::

    async with launch_sitl(home="egham", speedup=5) as sitl:
        ...  # SITL is running and has a position estimate
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(sitl.connection_url)

Everything MAVLink stays on loopback (:mod:`alphafence.sitl.cmdline`); instance numbers and
ports are reserved so that several instances run at once (:mod:`alphafence.sitl.ports`).

SITL exits when its parent process goes away, so the launching process stays its parent for
the whole session; shutdown is by process id: SIGTERM, then SIGKILL after a timeout.

A reboot (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN) makes SITL re-execute itself in place: the same
process (still the launcher's child), working directory and loopback ports; what it saved is
still there (``eeprom.bin``, and with ``BRD_SD_FENCE`` above 0 the fence in ``fence.stg``).
Its heartbeats stop for a few seconds meanwhile (3.2 s at speedup 1, measured).

Readiness (:meth:`SitlInstance.wait_ready`) listens on the instance's UDP port itself
(:mod:`alphafence.sitl.readiness`) and closes it before returning, so MAVSDK or pymavlink can
bind the port next. Only one program can bind the port at a time: don't wait for readiness
while another client has it.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil
import signal
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path

from alphafence.errors import SitlError, need
from alphafence.sitl.cmdline import MODEL, defaults_files, sitl_command, write_param_file
from alphafence.sitl.find import NOT_FOUND_HELP, find_sitl_binary
from alphafence.sitl.homes import DEFAULT_HOME, Home, resolve_home
from alphafence.sitl.ports import (
    LOOPBACK,
    InstanceLock,
    claim_port,
    release_port,
    reserve_instance,
)
from alphafence.sitl.readiness import ReadinessListener, ReadyState

LOG_NAME = "sitl.log"


class SitlInstance:
    """One ArduPilot copter SITL process in its own temporary directory.

    ``async with SitlInstance(...) as sitl`` starts it (without waiting for readiness) and stops
    it on exit; :func:`launch_sitl` also waits for readiness.

    Parameters
    ----------
    home : str or Home
        A name in the homes file, or ``lat,lon,alt[,heading]``.
    speedup : float
        SITL's simulation speedup.
    instance : int, optional
        The SITL instance number (default: the lowest free one).
    params : iterable of path
        Extra defaults files, loaded after the kit's.
    param_values : mapping, optional
        Parameter names to values, written to one more defaults file in the working directory.
    port : int, optional
        The loopback UDP port SITL sends MAVLink to (default: a free one).
    binary : path, optional
        The arducopter binary (default: :func:`~alphafence.sitl.find.find_sitl_binary`).
    model : str
        SITL's ``--model``.
    keep_dir : bool
        Keep the working directory (its ``sitl.log``) after stopping.
    radio : bool
        Open a second MAVLink link on SERIAL1 (``radio_url``): ArduPilot trusts channel 0
        (SERIAL0, "USB") with unsigned messages once signing is on, channel 1 it does not.
    serial1 : str, optional
        SERIAL1 as SITL takes a device instead (``uart:PATH:BAUD``: MAVLink on a serial port,
        channel 1, e.g. one end of a pseudo-terminal pair).
    """

    def __init__(
        self,
        home: str | Home = DEFAULT_HOME,
        *,
        speedup: float = 1,
        instance: int | None = None,
        params: Iterable[str | Path] = (),
        param_values: Mapping[str, float] | None = None,
        port: int | None = None,
        binary: str | Path | None = None,
        model: str = MODEL,
        keep_dir: bool = False,
        radio: bool = False,
        serial1: str | None = None,
    ):
        self.home = resolve_home(home)
        self.speedup = speedup
        self.requested_instance = instance
        self.params = [Path(p) for p in params]
        self.param_values = dict(param_values or {})
        self.requested_port = port
        self.binary = Path(binary) if binary is not None else None
        self.model = model
        self.keep_dir = keep_dir
        self.radio = radio
        self.serial1 = serial1
        self.radio_port: int | None = None
        self.instance: int | None = None
        self.port: int | None = None
        self.workdir: Path | None = None
        self.argv: list[str] | None = None
        self.process: asyncio.subprocess.Process | None = None
        self.state = ReadyState()
        self._lock: InstanceLock | None = None
        self._port_reserved = False
        self._closed = False

    # -- addresses

    @property
    def connection_url(self) -> str:
        """For MAVSDK: ``udpin://127.0.0.1:PORT``."""
        return f"udpin://{LOOPBACK}:{self._port()}"

    @property
    def pymavlink_url(self) -> str:
        """For pymavlink's ``mavutil.mavlink_connection`` (and MAVProxy's ``--master``)."""
        return f"udpin:{LOOPBACK}:{self._port()}"

    @property
    def radio_url(self) -> str:
        """For MAVSDK: the SERIAL1 link (``radio=True``), ``udpin://127.0.0.1:PORT``."""
        if self.radio_port is None:
            raise SitlError("SITL instance has no radio link (start it with radio=True)")
        return f"udpin://{LOOPBACK}:{self.radio_port}"

    def _port(self) -> int:
        if self.port is None:
            raise SitlError("SITL instance not started")
        return self.port

    @property
    def pid(self) -> int | None:
        """SITL's process id (None before start)."""
        return self.process.pid if self.process is not None else None

    @property
    def log_path(self) -> Path | None:
        """SITL's output, ``sitl.log`` in its working directory (None before start)."""
        return self.workdir / LOG_NAME if self.workdir is not None else None

    @property
    def running(self) -> bool:
        """Whether SITL's process has been started and not exited."""
        return self.process is not None and self.process.returncode is None

    def log_tail(self, lines: int = 20) -> str:
        """The last ``lines`` lines of SITL's log (a placeholder when there is none)."""
        path = self.log_path
        if path is None or not path.is_file():
            return "(no log)"
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 16384))
            text = f.read().decode("utf-8", "replace")
        return "\n".join(text.splitlines()[-lines:]) or "(empty log)"

    def _error(self, what: str) -> SitlError:
        return SitlError(f"{what}\n--- last lines of {self.log_path}:\n{self.log_tail()}")

    # -- life cycle

    async def start(self) -> SitlInstance:
        """Reserve an instance number and port, write the parameter file and start SITL in a
        fresh temporary directory (without waiting for readiness). Raises SitlError when no
        binary is found or nothing is free; on any failure what was reserved is released."""
        if self.process is not None:
            raise SitlError("SITL instance already started")
        binary = self.binary or find_sitl_binary()
        if binary is None:
            raise SitlError(NOT_FOUND_HELP)
        self.binary = Path(binary)
        try:
            self._lock = reserve_instance(self.requested_instance)
            self.instance = self._lock.instance
            self.port = claim_port(self.requested_port)
            self._port_reserved = True
            if self.radio:
                self.radio_port = claim_port()
            self.workdir = Path(tempfile.mkdtemp(prefix=f"alphafence-sitl-{self.instance}-"))
            extra = list(self.params)
            if self.param_values:
                extra.append(write_param_file(self.workdir / "caller.parm", self.param_values))
            self.argv = sitl_command(
                self.binary,
                self.home,
                port=self.port,
                instance=self.instance,
                speedup=self.speedup,
                defaults=defaults_files(self.binary, extra),
                model=self.model,
                radio_port=self.radio_port,
                serial1=self.serial1,
            )
            with open(self.workdir / LOG_NAME, "wb") as log:
                log.write(("$ " + " ".join(self.argv) + "\n").encode())
                log.flush()
                self.process = await asyncio.create_subprocess_exec(
                    *self.argv,
                    cwd=self.workdir,
                    stdin=asyncio.subprocess.DEVNULL,
                    stdout=log,
                    stderr=asyncio.subprocess.STDOUT,
                    start_new_session=True,  # Ctrl-C reaches us, and we stop SITL in order
                )
        except BaseException:
            await self.stop()
            raise
        return self

    async def wait_ready(self, timeout: float = 60.0) -> ReadyState:
        """Wait until the vehicle has a position estimate: GPS fix >= 3D, EKF absolute
        horizontal position, a GLOBAL_POSITION_INT fix and a home position. Binds the
        instance's UDP port while waiting and releases it before returning. Raises SitlError
        (with the log's tail) if SITL exits or ``timeout`` seconds pass first."""
        if self.process is None:
            raise SitlError("SITL instance not started")
        need(("pymavlink", "waiting for SITL to be ready"))
        self.state = state = ReadyState()
        listener = ReadinessListener(state)
        try:
            await listener.open(LOOPBACK, self.port)
        except OSError as exc:
            raise SitlError(
                f"cannot listen on UDP {LOOPBACK}:{self.port} ({exc.strerror}); "
                "is a MAVLink client already connected?"
            ) from None
        exited = asyncio.ensure_future(self.process.wait())
        deadline = time.monotonic() + timeout
        try:
            next_ask = 0.0
            while not state.ready:
                now = time.monotonic()
                if exited.done():
                    raise self._error(
                        f"SITL exited with code {self.process.returncode} before it was ready"
                    )
                if now >= deadline:
                    raise self._error(
                        f"SITL instance {self.instance} not ready after {timeout:g} s: "
                        + state.describe()
                    )
                if state.system is not None and now >= next_ask:
                    listener.ask()  # at the first heartbeat, then once a second
                    next_ask = now + 1.0
                listener.changed.clear()
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(
                        listener.changed.wait(), timeout=max(0.01, min(0.5, deadline - now))
                    )
            listener.reset()
        finally:
            exited.cancel()
            await listener.close()  # the port is free again for whoever binds it next
        return state

    async def stop(self, timeout: float = 5.0) -> int | None:
        """Stop SITL by process id (SIGTERM, then SIGKILL after ``timeout`` s), remove the
        working directory and release the instance number and port. Returns the exit code."""
        if self._closed:
            return self.process.returncode if self.process else None
        self._closed = True
        try:
            if self.process is not None and self.process.returncode is None:
                try:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(self.process.pid, signal.SIGTERM)
                    try:
                        await asyncio.wait_for(self.process.wait(), timeout)
                    except asyncio.TimeoutError:
                        with contextlib.suppress(ProcessLookupError):
                            os.kill(self.process.pid, signal.SIGKILL)
                        await self.process.wait()
                except asyncio.CancelledError:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(self.process.pid, signal.SIGKILL)
                    raise
        finally:
            self._release()
        return self.process.returncode if self.process else None

    def _release(self) -> None:
        if self._port_reserved:
            release_port(self.port)
            release_port(self.radio_port)
            self._port_reserved = False
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        if self.workdir is not None and not self.keep_dir:
            shutil.rmtree(self.workdir, ignore_errors=True)

    async def __aenter__(self) -> SitlInstance:
        return await self.start()

    async def __aexit__(self, *exc) -> None:
        await self.stop()

    def __repr__(self) -> str:
        return f"<SitlInstance {self.home.name} I={self.instance} port={self.port} pid={self.pid}>"


@contextlib.asynccontextmanager
async def launch_sitl(
    home: str | Home = DEFAULT_HOME, *, ready_timeout: float | None = 60.0, **options
):
    """Start a SITL instance, wait (unless ``ready_timeout`` is None) until it has a position
    estimate, yield it, and stop it on exit. ``options`` as for :class:`SitlInstance`."""
    async with SitlInstance(home, **options) as sitl:
        if ready_timeout is not None:
            await sitl.wait_ready(ready_timeout)
        yield sitl
