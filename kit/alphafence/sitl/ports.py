"""SITL instance numbers and UDP ports, reserved so that several instances run at once.

Everything MAVLink stays on loopback (:data:`LOOPBACK`); the one socket ArduPilot gives no
option for is its RC-input UDP port, ``RCIN_BASE_PORT + 10 * instance``, bound to all
interfaces. Instance numbers are therefore reserved across processes (an exclusive lock file
per instance, :class:`InstanceLock`) and skipped when their RC port is taken. The MAVLink
ports handed to the live instances of this process are remembered (:func:`claim_port`,
:func:`release_port`), so two instances never get the same one.
"""

from __future__ import annotations

import errno
import os
import socket
import tempfile
from pathlib import Path

from alphafence.errors import SitlError

LOOPBACK = "127.0.0.1"
RCIN_BASE_PORT = 5501  # SITL's RC-input UDP port is RCIN_BASE_PORT + 10 * instance
MAX_INSTANCE = 99

_ports_in_use: set[int] = set()  # handed to the live SITL instances of this process


def _udp_bindable(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def free_udp_port() -> int:
    """A loopback UDP port nobody is bound to now (and not handed out to a live instance)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((LOOPBACK, 0))
            port = s.getsockname()[1]
        if port not in _ports_in_use:
            return port
    raise SitlError("no free UDP port on loopback")


def claim_port(port: int | None = None) -> int:
    """Hand ``port`` (default: a free one) to a SITL instance until :func:`release_port`.
    Raises SitlError when another instance of this process has it."""
    port = port or free_udp_port()
    if port in _ports_in_use:
        raise SitlError(f"UDP port {port} is already used by another SITL instance")
    _ports_in_use.add(port)
    return port


def release_port(port: int | None) -> None:
    """Take back a port :func:`claim_port` handed out (None: nothing)."""
    _ports_in_use.discard(port)


def lock_dir() -> Path:
    """The directory of the instance lock files (per user, in the temporary directory)."""
    return Path(tempfile.gettempdir()) / f"alphafence-sitl-locks-{os.getuid()}"


class InstanceLock:
    """SITL instance number ``instance`` reserved across processes (an exclusive flock).

    Parameters
    ----------
    instance : int
        The instance number held.
    fd : int
        The open lock file holding the flock.
    """

    def __init__(self, instance: int, fd: int):
        self.instance = instance
        self._fd = fd

    @classmethod
    def try_acquire(cls, instance: int) -> InstanceLock | None:
        """The lock of ``instance``, or None when another process holds it."""
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
        """Give the instance number back (idempotent)."""
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
