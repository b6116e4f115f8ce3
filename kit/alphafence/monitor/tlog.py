"""The monitor's telemetry log: every MAVLink frame the vehicle sent, as a ``.tlog``.

A ``.tlog`` is what MAVProxy, QGroundControl and Mission Planner record: each frame as it
came, after its arrival time (8 bytes, big-endian, UNIX microseconds). ``alphafence
check-flight`` and log viewers read it. Frames are kept in memory as they arrive (no I/O on the
event loop) and appended to the file by a task of its own every half second and at the end.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
import time

FLUSH_S = 0.5  # how often the buffered frames are appended to the file
_STAMP = struct.Struct(">Q")


class TlogRecorder:
    """``recorder.frame(buf)`` for each frame; ``await recorder.close()`` at the end.

    Parameters
    ----------
    path : str or Path
        The ``.tlog`` to write (replaced: a new flight, a new log).

    Attributes
    ----------
    frames : int
        Frames recorded.
    error : str or None
        Why the file could not be written (frames after that are dropped, the monitor goes on).
    """

    def __init__(self, path):
        self.path = path
        self.frames = 0
        self.error: str | None = None
        self._buffer = bytearray()
        self._task: asyncio.Task | None = None
        self._stop = asyncio.Event()

    def frame(self, buf: bytes) -> None:
        """Record one frame, stamped with the wall clock now (no I/O here)."""
        if self.error is None:
            self._buffer += _STAMP.pack(int(time.time() * 1e6))
            self._buffer += buf
            self.frames += 1

    async def open(self) -> TlogRecorder:
        """Create the file (empty) and start appending to it."""
        await asyncio.to_thread(_write, self.path, b"", "wb")
        self._task = asyncio.create_task(self._run(), name="tlog")
        return self

    async def close(self) -> None:
        """Append what is left and stop."""
        self._stop.set()
        if self._task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        await self._flush()

    async def _run(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._stop.wait(), FLUSH_S)
            await self._flush()

    async def _flush(self) -> None:
        if not self._buffer or self.error is not None:
            return
        data, self._buffer = bytes(self._buffer), bytearray()
        try:
            await asyncio.to_thread(_write, self.path, data, "ab")
        except OSError as exc:
            self.error = f"{self.path}: cannot write the telemetry log: {exc.strerror}"


async def record_link(vehicle, path) -> TlogRecorder:
    """Record every frame ``vehicle`` sends (on the pymavlink link) to the ``.tlog`` ``path``.

    Parameters
    ----------
    vehicle : PymavlinkVehicle
        A connected vehicle whose ``link`` takes a recorder.
    path : str or Path

    Returns
    -------
    TlogRecorder
        Recording; ``await recorder.close()`` at the end.

    Raises
    ------
    InputError
        The vehicle's link gives no frames (MAVSDK's).
    """
    from alphafence.errors import InputError

    link = getattr(vehicle, "link", None)
    if link is None or not hasattr(link, "recorder"):
        raise InputError("--tlog", "records the pymavlink link's frames: use --link pymavlink")
    recorder = await TlogRecorder(path).open()
    link.recorder = recorder.frame
    return recorder


def check_tlog_path(path) -> None:
    """Refuse a telemetry log that cannot be written, before any link is opened.

    Raises
    ------
    InputError
        ``cannot write the telemetry log: <reason>``, naming ``path``.
    """
    from alphafence.errors import InputError

    try:
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise InputError(path, f"cannot write the telemetry log: {exc.strerror}") from None


def _write(path, data: bytes, mode: str) -> None:
    with open(path, mode) as fh:
        fh.write(data)
