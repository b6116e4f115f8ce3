"""A pseudo-terminal pair from socat (a serial cable in software), and the scripted vehicle of
tests/fake_vehicle.py on a byte stream (one end of the pair, or a TCP connection) instead of UDP.

``pty_pair`` starts ``socat -d -d pty,raw,echo=0,link=DIR/a pty,raw,echo=0,link=DIR/b`` and
returns ``(DIR/a, DIR/b)`` once socat says it is moving data (both links exist then); it skips
the test with one line when socat is not installed (Debian: apt-get install socat).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shutil

import pytest

from tests.fake_vehicle import FakeVehicle

SOCAT = shutil.which("socat")
NO_SOCAT = "socat is not installed (apt-get install socat): no pseudo-terminal pair"
READY = b"starting data transfer loop"


@contextlib.asynccontextmanager
async def socat_pair(directory):
    """``async with socat_pair(dir) as (a, b)``: the two ends of a pseudo-terminal pair."""
    a, b = os.path.join(directory, "a"), os.path.join(directory, "b")
    proc = await asyncio.create_subprocess_exec(
        SOCAT, "-d", "-d", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}",
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    said = []
    drain = None
    try:

        async def ready():
            while line := await proc.stderr.readline():
                said.append(line)
                if READY in line:
                    return
            raise AssertionError(f"socat ended: {b''.join(said).decode()}")

        await asyncio.wait_for(ready(), 10)
        assert os.path.islink(a) and os.path.islink(b)
        drain = asyncio.create_task(proc.stderr.read())  # socat's later notices
        yield a, b
    finally:
        if proc.returncode is None:
            proc.terminate()
        await proc.wait()
        if drain is not None:
            drain.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await drain


@pytest.fixture
async def pty_pair(tmp_path):
    if SOCAT is None:
        pytest.skip(NO_SOCAT)
    async with socat_pair(str(tmp_path)) as pair:
        yield pair


class StreamFake(FakeVehicle):
    """The scripted vehicle on a byte stream: subclasses open it and write to it."""

    class _Open:  # stands for the UDP transport FakeVehicle checks before sending
        pass

    async def start(self):
        self._loop = asyncio.get_running_loop()
        await self._open_stream()
        self._wire.transport = self._Open()
        self._tasks = [asyncio.create_task(self._heartbeats()), asyncio.create_task(self._update())]
        return self

    async def stop(self):
        await self._cancel_tasks()
        self._wire.transport = None
        await self._close_stream()

    def _data(self, data: bytes) -> None:
        if not self.disconnected:
            self._heard = True
            self._wire.feed(data)


class PtyFake(StreamFake):
    """The scripted vehicle on the serial device ``path`` (one end of a pty pair)."""

    def __init__(self, path, **options):
        super().__init__(**options)
        self.path = path
        self._fd = None

    async def _open_stream(self):
        self._fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self._loop.add_reader(self._fd, self._readable)

    def _readable(self):
        with contextlib.suppress(BlockingIOError):
            self._data(os.read(self._fd, 65536))

    def _sendto(self, data):
        if not self.disconnected and self._fd is not None:
            os.write(self._fd, data)

    async def _close_stream(self):
        if self._fd is not None:
            self._loop.remove_reader(self._fd)
            os.close(self._fd)
            self._fd = None


class TcpFake(StreamFake):
    """The scripted vehicle connecting over TCP to ``port`` on loopback (the kit's tcpin)."""

    def __init__(self, port, **options):
        super().__init__(**options)
        self.tcp_port = port
        self._writer = None
        self._reader_task = None

    async def _open_stream(self):
        reader, self._writer = await asyncio.open_connection("127.0.0.1", self.tcp_port)

        async def read():
            while data := await reader.read(65536):
                self._data(data)

        self._reader_task = asyncio.create_task(read())

    def _sendto(self, data):
        if not self.disconnected and self._writer is not None:
            self._writer.write(data)

    async def _close_stream(self):
        if self._reader_task is not None:
            self._reader_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionError):
                await self._reader_task
        if self._writer is not None:
            self._writer.close()
            with contextlib.suppress(ConnectionError):
                await self._writer.wait_closed()
