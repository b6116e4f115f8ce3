"""Write outputs all-or-nothing: every file goes to a temporary sibling first, and only when
all of them are complete are they renamed into place."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0o022)  # read it the only way POSIX offers: set and put back
    os.umask(mask)
    return mask


def temp_beside(path):
    """A temporary sibling of ``path`` for an all-or-nothing write: ``(fd, name)``, opened
    for writing, with the permissions a new file at ``path`` would get (``0666 & ~umask``,
    where ``mkstemp`` alone gives ``0600``).

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     fd, tmp = temp_beside(os.path.join(d, "fences.geojson"))
    ...     os.close(fd)
    ...     mode = os.stat(tmp).st_mode & 0o777
    >>> mode == 0o666 & ~_umask(), os.path.basename(tmp).startswith(".fences.geojson.")
    (True, True)
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.fchmod(fd, 0o666 & ~_umask())
    return fd, tmp


def write_all(outputs: dict):
    """Write several text files all or nothing: either every file is written, or none is
    changed.

    Parameters
    ----------
    outputs : dict
        ``{path: text or bytes}``; parent folders are made as needed. Text is written as
        UTF-8 with ``\\n`` line ends, bytes as they are, each synced to disk before any file
        is renamed into place.
    """
    temps = []
    try:
        for path, text in outputs.items():
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = temp_beside(path)
            temps.append((tmp, path))
            binary = isinstance(text, (bytes, bytearray))
            text_mode = {} if binary else {"encoding": "utf-8", "newline": "\n"}
            with os.fdopen(fd, "wb" if binary else "w", **text_mode) as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, path in temps:
            os.replace(tmp, path)
        temps = []
    finally:
        for tmp, _ in temps:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass


def write_bytes_atomic(path, data: bytes):
    """Write ``data`` to ``path`` through a temporary sibling, so ``path`` is either left as
    it was or holds all of ``data``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = temp_beside(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
