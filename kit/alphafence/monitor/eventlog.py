"""The monitor's event log: every event kept in memory, passed to its listeners and appended to
a JSON-lines file by a task of its own (file I/O never blocks the event loop).

A log that cannot be written never stops, hangs or grows the monitor: the failure is reported
once (a ``log_write_failed`` event), the lines it held are counted as lost, and the writer goes
on with the next ones.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import deque

from alphafence.monitor.events import new_event


class EventLog:
    """JSON lines, appended by a background task.

    Parameters
    ----------
    path : str or Path, optional
        The file to append to; None keeps the events in memory only.
    echo : callable, optional
        Called with every event as it is put (the CLI prints them); the first listener.
    keep : int
        How many of the latest events ``events`` keeps in memory (for tests and the summary).
    clock : UtcClock, optional
        Where the events' UTC comes from: the file's first line written is then a ``clock``
        event saying so (``utc_source``, with ``fields``); it is not kept nor passed on.
    **fields
        Added to the ``clock`` event (e.g. ``replay=True``).

    Attributes
    ----------
    events : collections.deque
        The latest ``keep`` events.
    lost : int
        Lines that could not be written.
    write_error : str or None
        The last write failure, until a write succeeds again.
    """

    def __init__(self, path=None, echo=None, keep: int = 10_000, clock=None, **fields):
        self.path = path
        self.listeners = [echo] if echo else []
        self.queue: asyncio.Queue = asyncio.Queue()
        self.task = asyncio.create_task(self._write()) if path else None
        if self.task and clock is not None:
            self.queue.put_nowait(json.dumps(clock.event(**fields), separators=(",", ":")))
        self.events: deque = deque(maxlen=keep)
        self.lost = 0
        self.write_error: str | None = None

    def add_listener(self, listener) -> None:
        """Call ``listener(event)`` with every event put from now on, after those before it."""
        self.listeners.append(listener)

    def put(self, event: dict) -> None:
        """Keep ``event``, pass it to every listener and queue it for the file.

        Parameters
        ----------
        event : dict
            An event from :func:`alphafence.monitor.events.new_event`.
        """
        self.events.append(event)
        for listener in self.listeners:
            listener(event)
        if self.task and not self.task.done():
            self.queue.put_nowait(json.dumps(event, separators=(",", ":")))

    async def _write(self):
        while True:
            lines = [await self.queue.get()]
            while not self.queue.empty():
                lines.append(self.queue.get_nowait())
            try:
                await asyncio.to_thread(_append, self.path, lines)
            except OSError as exc:
                self.lost += len(lines)
                if self.write_error is None:
                    self.write_error = f"{self.path}: {exc.strerror or exc}"
                    self.put(new_event("log_write_failed", error=self.write_error))
            else:
                self.write_error = None

    async def close(self, timeout: float = 5.0) -> None:
        """Write what is queued (for at most ``timeout`` seconds; the rest is counted as
        lost) and stop the writer."""
        if self.task:
            deadline = time.monotonic() + timeout
            while not self.queue.empty() and not self.task.done():
                if time.monotonic() > deadline:
                    self.lost += self.queue.qsize()
                    break
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.05)
            self.task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self.task


def check_log_path(path) -> None:
    """Refuse an event log that cannot be appended to, before any link is opened.

    Raises
    ------
    InputError
        ``cannot write the event log: <reason>``, naming ``path``.
    """
    from alphafence.errors import InputError

    try:
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        raise InputError(path, f"cannot write the event log: {exc.strerror}") from None


def _append(path, lines):
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
