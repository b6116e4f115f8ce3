"""Byte streams to the vehicle on the asyncio loop: a serial port, a TCP connection we make,
and a TCP port we listen on for the vehicle.

Each has the same small interface, which :class:`~alphafence.vehicle.bridge.VehicleLink` puts
its MAVLink codec on: ``await open()``, ``write(data) -> bool`` (False when there is nowhere to
send yet), ``await close()``, and ``closed``, the reason the stream ended (None while it
lives). Bytes received go to ``on_data(data)``.

No blocking call runs on the loop: the serial port is opened by pyserial in a worker thread,
then read and written through its file descriptor, non-blocking, with ``loop.add_reader`` and
``loop.add_writer`` (where a loop has no such calls, as Windows' has not, a worker thread reads
and writes). Errors an operator can act on (no such port, permission denied, a port another
program holds) are one line each, naming the port.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
from collections.abc import Callable

from alphafence.errors import VehicleError, need
from alphafence.vehicle.endpoints import Endpoint

CHUNK = 65536
MAX_PENDING = 65536  # bytes waiting for a slow serial port; more is dropped, never queued


class TransportError(VehicleError):
    """The connection to the vehicle could not be opened (one line, naming it)."""


def serial_error(device: str, baud: int, exc: BaseException) -> TransportError:
    """The operator's line for a serial port that would not open.

    Parameters
    ----------
    device, baud : str, int
        The port and speed asked for.
    exc : BaseException
        pyserial's or the system's error.

    Examples
    --------
    >>> str(serial_error("/dev/ttyACM0", 115200, PermissionError(13, "Permission denied")))
    '/dev/ttyACM0: permission denied: add your user to the dialout group (sudo usermod -aG dialout $USER, then log in again)'
    """
    code = getattr(exc, "errno", None)
    text = str(exc)
    if code in (errno.ENOENT, errno.ENODEV, errno.ENXIO) or "No such file" in text:
        return TransportError(
            f"{device}: no such serial port (is the vehicle plugged in? ls /dev/serial/by-id/)"
        )
    if code in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
        return TransportError(
            f"{device}: permission denied: add your user to the dialout group "
            "(sudo usermod -aG dialout $USER, then log in again)"
        )
    if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text:
        return TransportError(
            f"{device}: busy: another program has the port open (a ground station, MAVProxy, "
            "mavlink-router, ModemManager); close it first"
        )
    if "baud" in text.lower():
        return TransportError(f"{device}: the port does not take {baud} baud ({text})")
    return TransportError(f"{device}: cannot open the serial port ({text})")


class SerialPort:
    """A serial port (USB or a telemetry radio) as a byte stream.

    Parameters
    ----------
    endpoint : Endpoint
        A ``serial`` endpoint (device, baud, flow control).
    on_data : callable
        ``on_data(bytes)`` for what the vehicle sends.
    """

    def __init__(self, endpoint: Endpoint, on_data: Callable[[bytes], None]):
        self.endpoint = endpoint
        self.on_data = on_data
        self.closed: str | None = None
        self.ended = asyncio.Event()  # set when the port went away (``closed`` says how)
        self.dropped = 0  # bytes not sent: the port could not take them fast enough
        self._serial = None
        self._fd: int | None = None
        self._pending = bytearray()
        self._thread_task: asyncio.Task | None = None

    async def open(self) -> SerialPort:
        """Open the port. Raises TransportError (one line) when it cannot be opened."""
        need(("serial", "a serial port"))
        import serial

        ep = self.endpoint

        def _open():
            return serial.Serial(
                ep.device,
                ep.baud,
                timeout=0,
                write_timeout=0,
                rtscts=ep.flow_control,
                exclusive=True if os.name == "posix" else None,
            )

        try:
            self._serial = await asyncio.to_thread(_open)
        except (OSError, ValueError, serial.SerialException) as exc:
            raise serial_error(ep.device, ep.baud, exc) from None
        loop = asyncio.get_running_loop()
        try:
            fd = self._serial.fileno()
            os.set_blocking(fd, False)
            loop.add_reader(fd, self._readable)
            self._fd = fd
        except (AttributeError, NotImplementedError, OSError, ValueError):
            self._serial.timeout = 0.1  # a worker thread reads (Windows' loop has no readers)
            self._thread_task = asyncio.create_task(self._read_in_thread())
        return self

    def write(self, data: bytes) -> bool:
        """Send ``data`` (queued when the port is busy). False once the port is closed."""
        if self._serial is None or self.closed is not None:
            return False
        if self._fd is None:
            asyncio.get_running_loop().run_in_executor(None, self._write_blocking, bytes(data))
            return True
        if self._pending:
            self._queue(data)
            return True
        try:
            sent = os.write(self._fd, data)
        except BlockingIOError:
            sent = 0
        except OSError as exc:
            self._lost(exc)
            return False
        if sent < len(data):
            self._queue(memoryview(data)[sent:])
            asyncio.get_running_loop().add_writer(self._fd, self._writable)
        return True

    def _queue(self, data) -> None:
        if len(self._pending) + len(data) > MAX_PENDING:
            self.dropped += len(data)
        else:
            self._pending += data

    def _writable(self) -> None:
        try:
            sent = os.write(self._fd, self._pending)
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(exc)
            return
        del self._pending[:sent]
        if not self._pending:
            asyncio.get_running_loop().remove_writer(self._fd)

    def _readable(self) -> None:
        try:
            data = os.read(self._fd, CHUNK)
        except BlockingIOError:
            return
        except OSError as exc:
            self._lost(exc)
            return
        if not data:
            self._lost(None)
            return
        self.on_data(data)

    def _lost(self, exc) -> None:
        why = f" ({exc.strerror or exc})" if isinstance(exc, OSError) else ""
        self.closed = f"the serial port {self.endpoint.device} went away{why}"
        self.ended.set()
        self._detach()

    def _detach(self) -> None:
        if self._fd is not None:
            loop = asyncio.get_running_loop()
            loop.remove_reader(self._fd)
            loop.remove_writer(self._fd)
            self._fd = None

    async def _read_in_thread(self) -> None:
        port = self._serial
        while self.closed is None:
            try:
                data = await asyncio.to_thread(port.read, max(1, port.in_waiting))
            except Exception as exc:  # pyserial's SerialException, or the port gone
                self.closed = f"the serial port {self.endpoint.device} went away ({exc})"
                self.ended.set()
                return
            if data:
                self.on_data(data)

    def _write_blocking(self, data: bytes) -> None:
        with contextlib.suppress(Exception):
            self._serial.write(data)

    async def close(self) -> None:
        """Close the port."""
        self._detach()
        if self._thread_task is not None:
            self._thread_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._thread_task
        if self._serial is not None:
            port, self._serial = self._serial, None
            with contextlib.suppress(Exception):
                port.close()


class TcpClient:
    """A TCP connection to the vehicle (``tcpout``).

    Parameters
    ----------
    endpoint : Endpoint
        Where the vehicle listens.
    on_data : callable
        ``on_data(bytes)`` for what the vehicle sends.
    """

    def __init__(self, endpoint: Endpoint, on_data: Callable[[bytes], None]):
        self.endpoint = endpoint
        self.on_data = on_data
        self.closed: str | None = None
        self._writer = None
        self._task: asyncio.Task | None = None

    async def open(self) -> TcpClient:
        """Connect (within 10 s). Raises TransportError when it cannot."""
        try:
            reader, self._writer = await asyncio.wait_for(
                asyncio.open_connection(*self.endpoint.address), 10.0
            )
        except (OSError, asyncio.TimeoutError) as exc:
            raise TransportError(f"{self.endpoint}: cannot open the connection ({exc})") from None
        self._task = asyncio.create_task(self._read(reader))
        return self

    async def _read(self, reader) -> None:
        self.closed = await read_stream(reader, self.on_data)

    def write(self, data: bytes) -> bool:
        """Send ``data``; False once the connection is closed."""
        if self._writer is None or self.closed is not None:
            return False
        self._writer.write(data)
        return True

    async def close(self) -> None:
        """Close the connection."""
        await _stop(self._task)
        await _close_writer(self._writer)
        self._writer = self._task = None


class TcpListener:
    """A TCP port the vehicle connects to (``tcpin``): one vehicle at a time; when it
    disconnects, the next connection is taken (a vehicle that rebooted comes back).

    Parameters
    ----------
    endpoint : Endpoint
        The address to listen on.
    on_data : callable
        ``on_data(bytes)`` for what the vehicle sends.
    """

    def __init__(self, endpoint: Endpoint, on_data: Callable[[bytes], None]):
        self.endpoint = endpoint
        self.on_data = on_data
        self.closed: str | None = None
        self.peer = None  # the vehicle's address while it is connected
        self._server = None
        self._writer = None

    async def open(self) -> TcpListener:
        """Listen. Raises TransportError when the address cannot be bound."""
        try:
            self._server = await asyncio.start_server(self._vehicle, *self.endpoint.address)
        except OSError as exc:
            raise TransportError(f"{self.endpoint}: cannot listen ({exc})") from None
        return self

    @property
    def sockname(self):
        """The address listened on (the port chosen, when 0 was asked)."""
        return self._server.sockets[0].getsockname() if self._server else None

    async def _vehicle(self, reader, writer) -> None:
        if self._writer is not None:
            await _close_writer(writer)  # one vehicle at a time
            return
        self._writer, self.peer, self.closed = writer, writer.get_extra_info("peername"), None
        try:
            why = await read_stream(reader, self.on_data)
        finally:
            if self._writer is writer:
                self._writer = self.peer = None
                self.closed = why if self._server is not None else None
            await _close_writer(writer)

    def write(self, data: bytes) -> bool:
        """Send ``data``; False while no vehicle is connected."""
        if self._writer is None:
            return False
        self._writer.write(data)
        return True

    async def close(self) -> None:
        """Stop listening and close the vehicle's connection."""
        server, self._server = self._server, None
        if server is not None:
            server.close()
        await _close_writer(self._writer)
        if server is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(server.wait_closed(), 5.0)


async def read_stream(reader, on_data) -> str:
    """Hand what ``reader`` gives to ``on_data`` until the stream ends; the reason it ended."""
    try:
        while data := await reader.read(CHUNK):
            on_data(data)
    except OSError as exc:
        return f"the connection failed ({exc})"
    return "the vehicle closed the connection"


async def _stop(task) -> None:
    if task is not None:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task


async def _close_writer(writer) -> None:
    if writer is not None:
        writer.close()
        with contextlib.suppress(Exception):
            await writer.wait_closed()


def stream_transport(endpoint: Endpoint, on_data: Callable[[bytes], None]):
    """The byte stream for a ``serial``, ``tcpout`` or ``tcpin`` endpoint.

    Parameters
    ----------
    endpoint : Endpoint
        The connection.
    on_data : callable
        ``on_data(bytes)`` for what the vehicle sends.

    Returns
    -------
    SerialPort or TcpClient or TcpListener
        Not yet open.
    """
    kinds = {"serial": SerialPort, "tcpout": TcpClient, "tcpin": TcpListener}
    return kinds[endpoint.kind](endpoint, on_data)
