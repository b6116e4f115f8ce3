"""Launch ArduPilot copter SITL instances, one per fresh temporary directory, from asyncio.

::

    async with launch_sitl(home="egham", speedup=5) as sitl:
        ...  # SITL is running and has a position estimate
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(sitl.connection_url)

Everything MAVLink stays on loopback: SERIAL0 is ``udpclient:127.0.0.1:PORT`` (SITL sends to a
UDP port that *we* listen on, chosen free per instance), and SERIAL1/SERIAL2, which SITL would
otherwise open as TCP listeners on all interfaces, are ``none``. The one socket ArduPilot gives
no option for is its RC-input UDP port, 5501 + 10 * instance, bound to all interfaces; instance
numbers are therefore reserved across processes (a lock file per instance) and skipped when
their RC port is taken, so several instances run at once.

SITL exits when its parent process goes away, so the launching process stays its parent for
the whole session; shutdown is by process id: SIGTERM, then SIGKILL after a timeout.

Readiness (:meth:`SitlInstance.wait_ready`) listens on the instance's UDP port itself, with
pymavlink's MAVLink codec on an asyncio datagram endpoint (no thread, no blocking call), and
closes that endpoint before returning, so MAVSDK or pymavlink can bind the port next. Only one
program can bind the port at a time: don't wait for readiness while another client has it.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import math
import os
import re
import shutil
import signal
import socket
import tempfile
import time
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from alphafence.errors import InputError, SitlError
from alphafence.sitl.find import NOT_FOUND_HELP, ardupilot_tree, find_sitl_binary

LOOPBACK = "127.0.0.1"
MODEL = "+"  # a plus-frame quad; the kit's parameter file sets FRAME_CLASS 1, FRAME_TYPE 0
DEFAULT_HOME = "egham"
RCIN_BASE_PORT = 5501  # SITL's RC-input UDP port is RCIN_BASE_PORT + 10 * instance
MAX_INSTANCE = 99
COPTER_DEFAULTS = "Tools/autotest/default_params/copter.parm"  # inside an ArduPilot tree
LOG_NAME = "sitl.log"

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_PARAM = re.compile(r"^[A-Z][A-Z0-9_]{0,15}$")


# ---------------------------------------------------------------------------------------------
# data files: kit/alphafence/data/sitl (sitl/ at the repository root links to them)


def data_path(name: str) -> Path:
    """A file of the kit's SITL data (``homes.toml``, ``alphafence-test.parm``)."""
    return Path(str(resources.files("alphafence").joinpath("data/sitl", name)))


def kit_parm_path() -> Path:
    """The kit's own SITL parameter file."""
    return data_path("alphafence-test.parm")


@dataclass(frozen=True)
class Home:
    name: str
    lat: float
    lon: float
    alt: float
    heading: float = 0.0
    description: str = ""

    def arg(self) -> str:
        """The ``--home`` argument: ``lat,lon,alt,heading``."""
        return ",".join(_num(v) for v in (self.lat, self.lon, self.alt, self.heading))


def _num(value: float) -> str:
    return f"{value:.7f}".rstrip("0").rstrip(".") if value != int(value) else str(int(value))


def _check_home(path, name, lat, lon, alt, heading) -> None:
    for key, value in (("lat", lat), ("lon", lon), ("alt", alt), ("heading", heading)):
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise InputError(path, f"{key} must be a finite number, not {value!r}", name)
    if not -90 <= lat <= 90:
        raise InputError(path, f"lat {lat} is outside -90..90", name)
    if not -180 <= lon <= 180:
        raise InputError(path, f"lon {lon} is outside -180..180", name)
    if not -500 <= alt <= 9000:
        raise InputError(path, f"alt {alt} m is outside -500..9000", name)
    if not 0 <= heading < 360:
        raise InputError(path, f"heading {heading} is outside 0..360", name)


def parse_homes(text: str, path: str | Path = "homes.toml") -> dict[str, Home]:
    """Named homes from TOML text: one table per name with lat, lon, alt, optional heading and
    description. Raises InputError naming the file and the home."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, f"not valid TOML: {exc}") from None
    homes = {}
    for name, table in doc.items():
        if not isinstance(table, dict):
            raise InputError(path, "each home must be a table: [name] with lat, lon, alt", name)
        if not _NAME.match(name):
            raise InputError(path, "names are lower case letters, digits and _", name)
        unknown = set(table) - {"lat", "lon", "alt", "heading", "description"}
        if unknown:
            raise InputError(path, f"unknown keys {sorted(unknown)}", name)
        missing = [k for k in ("lat", "lon", "alt") if k not in table]
        if missing:
            raise InputError(path, f"missing {', '.join(missing)}", name)
        heading = table.get("heading", 0)
        _check_home(path, name, table["lat"], table["lon"], table["alt"], heading)
        homes[name] = Home(
            name,
            float(table["lat"]),
            float(table["lon"]),
            float(table["alt"]),
            float(heading),
            str(table.get("description", "")),
        )
    if not homes:
        raise InputError(path, "no homes defined")
    return homes


def load_homes(path: str | Path | None = None) -> dict[str, Home]:
    """The kit's named homes, or those of another homes file."""
    if path is None:
        path = data_path("homes.toml")
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    return parse_homes(text, path)


def resolve_home(home: str | Home, homes: Mapping[str, Home] | None = None) -> Home:
    """A Home from a name in the homes file, or from ``lat,lon,alt[,heading]``."""
    if isinstance(home, Home):
        return home
    homes = load_homes() if homes is None else homes
    if home in homes:
        return homes[home]
    parts = home.split(",")
    if len(parts) in (3, 4):
        try:
            values = [float(p) for p in parts] + ([0.0] if len(parts) == 3 else [])
        except ValueError:
            values = None
        if values is not None:
            _check_home("--home", home, *values)
            return Home("custom", *values)
    known = ", ".join(sorted(homes))
    raise InputError("--home", f"unknown home {home!r}: use one of {known}, or lat,lon,alt,heading")


# ---------------------------------------------------------------------------------------------
# command line


def copter_defaults(binary: Path) -> Path | None:
    """ArduPilot's copter defaults from the tree ``binary`` was built in, if there is one."""
    tree = ardupilot_tree(Path(binary))
    return tree / COPTER_DEFAULTS if tree is not None else None


def defaults_files(binary: Path, extra: Iterable[str | Path] = ()) -> list[Path]:
    """SITL's ``--defaults`` list, in load order (later files win): ArduPilot's copter.parm
    (when the tree is found), the kit's own test file, then ``extra``."""
    files = []
    tree_defaults = copter_defaults(binary)
    if tree_defaults is not None:
        files.append(tree_defaults)
    files.append(kit_parm_path())
    files.extend(Path(p) for p in extra)
    return files


def sitl_command(
    binary: str | Path,
    home: Home,
    *,
    port: int,
    instance: int = 0,
    speedup: float = 1,
    defaults: Iterable[str | Path] = (),
    model: str = MODEL,
    radio_port: int | None = None,
) -> list[str]:
    """The SITL argument vector: MAVLink on SERIAL0 to ``udpin`` on loopback ``port``; SERIAL1
    and SERIAL2 (TCP listeners by default) switched off, or SERIAL1 to loopback ``radio_port``
    (a second MAVLink link, like a telemetry radio: ArduPilot's channel 1)."""
    defaults = [str(p) for p in defaults]
    for path in defaults:
        if "," in path:
            raise SitlError(f"SITL takes a comma-separated defaults list; rename {path}")
    if not 0 <= instance <= MAX_INSTANCE:
        raise SitlError(f"instance {instance} is outside 0..{MAX_INSTANCE}")
    if not speedup > 0:
        raise SitlError(f"speedup must be positive, not {speedup}")
    argv = [
        str(binary),
        "--model", model,
        "--home", home.arg(),
        "--speedup", f"{speedup:g}",
        "-I", str(instance),
    ]  # fmt: skip
    if defaults:
        argv += ["--defaults", ",".join(defaults)]
    argv += [
        "--serial0", f"udpclient:{LOOPBACK}:{port}",
        "--serial1", "none" if radio_port is None else f"udpclient:{LOOPBACK}:{radio_port}",
        "--serial2", "none",
    ]  # fmt: skip
    return argv


def write_param_file(path: Path, values: Mapping[str, float]) -> Path:
    """A parameter file of ``NAME VALUE`` lines."""
    lines = ["# parameters set by the caller of the AlphaFence SITL launcher"]
    for name, value in values.items():
        if not _PARAM.match(name):
            raise SitlError(f"not an ArduPilot parameter name: {name!r}")
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise SitlError(f"parameter {name} must be a finite number, not {value!r}")
        lines.append(f"{name} {value!r}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------
# ports and instance numbers


def _udp_bindable(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


_ports_in_use: set[int] = set()


def free_udp_port() -> int:
    """A loopback UDP port nobody is bound to now (and not handed out to a live instance)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((LOOPBACK, 0))
            port = s.getsockname()[1]
        if port not in _ports_in_use:
            return port
    raise SitlError("no free UDP port on loopback")


def lock_dir() -> Path:
    return Path(tempfile.gettempdir()) / f"alphafence-sitl-locks-{os.getuid()}"


class InstanceLock:
    """SITL instance number ``instance`` reserved across processes (an exclusive flock)."""

    def __init__(self, instance: int, fd: int):
        self.instance = instance
        self._fd = fd

    @classmethod
    def try_acquire(cls, instance: int) -> InstanceLock | None:
        import fcntl

        directory = lock_dir()
        directory.mkdir(mode=0o700, exist_ok=True)
        fd = os.open(directory / f"instance-{instance}.lock", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                return None
            raise
        return cls(instance, fd)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock
            self._fd = None


def reserve_instance(instance: int | None = None) -> InstanceLock:
    """Reserve ``instance``, or the lowest free one: not locked by another AlphaFence launcher
    and with its RC-input port (5501 + 10 * I, SITL binds it on all interfaces) unused."""
    wanted = range(MAX_INSTANCE + 1) if instance is None else [instance]
    for i in wanted:
        if not 0 <= i <= MAX_INSTANCE:
            raise SitlError(f"instance {i} is outside 0..{MAX_INSTANCE}")
        lock = InstanceLock.try_acquire(i)
        if lock is None:
            if instance is not None:
                raise SitlError(f"SITL instance {i} is in use by another AlphaFence launcher")
            continue
        if _udp_bindable("", RCIN_BASE_PORT + 10 * i):
            return lock
        lock.release()
        if instance is not None:
            raise SitlError(
                f"SITL instance {i}: its RC-input UDP port {RCIN_BASE_PORT + 10 * i} is in use"
            )
    raise SitlError(f"no free SITL instance number in 0..{MAX_INSTANCE}")


# ---------------------------------------------------------------------------------------------
# readiness


@dataclass
class ReadyState:
    """What readiness watches, from the vehicle's own MAVLink messages."""

    system: tuple[int, int] | None = None  # (sysid, compid) of the autopilot
    gps_fix: int = 0
    ekf_flags: int | None = None
    position: tuple[float, float, float] | None = None  # lat, lon (deg), alt AMSL (m)
    home: tuple[float, float, float] | None = None  # lat, lon (deg), alt AMSL (m)
    status_texts: deque = field(default_factory=lambda: deque(maxlen=8))

    # EKF_STATUS_FLAGS
    POS_HORIZ_ABS = 16
    CONST_POS_MODE = 128
    PRED_POS_HORIZ_ABS = 512

    @property
    def ekf_position_ok(self) -> bool:
        """ArduPilot's own test while disarmed: an absolute (or predicted absolute) horizontal
        position, and not in constant-position mode ("Need Position Estimate" otherwise)."""
        f = self.ekf_flags
        if f is None:
            return False
        return (
            bool(f & (self.POS_HORIZ_ABS | self.PRED_POS_HORIZ_ABS)) and not f & self.CONST_POS_MODE
        )

    @property
    def ready(self) -> bool:
        return (
            self.system is not None
            and self.gps_fix >= 3
            and self.ekf_position_ok
            and self.position is not None
            and self.home is not None
        )

    def describe(self) -> str:
        parts = [
            "heartbeat seen" if self.system else "no heartbeat",
            f"GPS fix type {self.gps_fix}",
            "no EKF status"
            if self.ekf_flags is None
            else f"EKF flags {self.ekf_flags:#x}"
            + ("" if self.ekf_position_ok else " (no absolute horizontal position yet)"),
            "position known" if self.position else "no position",
            "home set" if self.home else "home not set",
        ]
        text = ", ".join(parts)
        if self.status_texts:
            text += "; last messages: " + " | ".join(self.status_texts)
        return text

    def update(self, msg) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type != 6 and msg.autopilot != 8:  # not a GCS, not MAV_AUTOPILOT_INVALID
                self.system = (msg.get_srcSystem(), msg.get_srcComponent())
        elif kind == "GPS_RAW_INT":
            self.gps_fix = msg.fix_type
        elif kind == "EKF_STATUS_REPORT":
            self.ekf_flags = msg.flags
        elif kind == "GLOBAL_POSITION_INT":
            if msg.lat or msg.lon:
                self.position = (msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3)
        elif kind == "HOME_POSITION":
            self.home = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
        elif kind == "STATUSTEXT":
            self.status_texts.append(msg.text)


# messages readiness asks for while it waits, with their MAVLink ids
_WATCHED = {"GPS_RAW_INT": 24, "GLOBAL_POSITION_INT": 33, "EKF_STATUS_REPORT": 193}
_HOME_POSITION = 242
_MAV_CMD_SET_MESSAGE_INTERVAL = 511
_MAV_CMD_REQUEST_MESSAGE = 512


class _Listener(asyncio.DatagramProtocol):
    def __init__(self, state: ReadyState):
        from pymavlink.dialects.v20 import ardupilotmega

        self.mav = ardupilotmega.MAVLink(None, srcSystem=255, srcComponent=190)
        self.mav.robust_parsing = True
        self.state = state
        self.seen: set[str] = set()
        self.peer = None
        self.transport = None
        self.changed = asyncio.Event()
        self.closed = asyncio.get_running_loop().create_future()

    def connection_made(self, transport):
        self.transport = transport

    def connection_lost(self, exc):
        if not self.closed.done():
            self.closed.set_result(None)

    def datagram_received(self, data, addr):
        self.peer = addr
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception:  # a corrupt datagram: wait for the next one
            return
        for msg in msgs:
            if msg.get_type() != "BAD_DATA":
                self.seen.add(msg.get_type())
                self.state.update(msg)
        self.changed.set()

    def command(self, command: int, *params: float) -> None:
        if self.peer is None or self.state.system is None:
            return
        p = list(params) + [0.0] * (7 - len(params))
        msg = self.mav.command_long_encode(*self.state.system, command, 0, *p)
        self.transport.sendto(msg.pack(self.mav), self.peer)

    def ask(self) -> None:
        """Ask for the watched messages not seen yet (5 Hz), and for the home position."""
        for name, msgid in _WATCHED.items():
            if name not in self.seen:
                self.command(_MAV_CMD_SET_MESSAGE_INTERVAL, msgid, 200_000)
        if self.state.home is None:
            self.command(_MAV_CMD_REQUEST_MESSAGE, _HOME_POSITION)

    def reset(self) -> None:
        """The watched messages back to the vehicle's default rates."""
        for msgid in _WATCHED.values():
            self.command(_MAV_CMD_SET_MESSAGE_INTERVAL, msgid, 0)


# ---------------------------------------------------------------------------------------------
# the instance


class SitlInstance:
    """One ArduPilot copter SITL process in its own temporary directory.

    ``async with SitlInstance(...) as sitl`` starts it (without waiting for readiness) and stops
    it on exit; :func:`launch_sitl` also waits for readiness.

    ``params`` are extra defaults files (loaded after the kit's), ``param_values`` a mapping
    of parameter names to values written to one more defaults file in the working directory.
    ``port`` is the loopback UDP port SITL sends MAVLink to (default: a free one).
    ``radio=True`` opens a second MAVLink link on SERIAL1 (``radio_url``): ArduPilot trusts
    channel 0 (SERIAL0, "USB") with unsigned messages once signing is on, channel 1 it does not.
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
        return self.process.pid if self.process is not None else None

    @property
    def log_path(self) -> Path | None:
        return self.workdir / LOG_NAME if self.workdir is not None else None

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.returncode is None

    def log_tail(self, lines: int = 20) -> str:
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
        if self.process is not None:
            raise SitlError("SITL instance already started")
        binary = self.binary or find_sitl_binary()
        if binary is None:
            raise SitlError(NOT_FOUND_HELP)
        self.binary = Path(binary)
        try:
            self._lock = reserve_instance(self.requested_instance)
            self.instance = self._lock.instance
            self.port = self.requested_port or free_udp_port()
            if self.port in _ports_in_use:
                raise SitlError(f"UDP port {self.port} is already used by another SITL instance")
            _ports_in_use.add(self.port)
            self._port_reserved = True
            if self.radio:
                self.radio_port = free_udp_port()
                _ports_in_use.add(self.radio_port)
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
        try:
            import pymavlink  # noqa: F401
        except ModuleNotFoundError:
            raise SitlError(
                "readiness needs pymavlink: pip install 'alphafence[vehicle]'"
            ) from None
        loop = asyncio.get_running_loop()
        self.state = state = ReadyState()
        try:
            transport, listener = await loop.create_datagram_endpoint(
                lambda: _Listener(state), local_addr=(LOOPBACK, self.port)
            )
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
            transport.close()  # the socket closes on a later turn of the loop: wait for it,
            await listener.closed  # so whoever binds the port next finds it free
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
            _ports_in_use.discard(self.port)
            _ports_in_use.discard(self.radio_port)
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
