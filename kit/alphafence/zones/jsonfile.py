"""Files read whole with a size limit and one-line errors: JSON, and raw bytes."""

from __future__ import annotations

import json
import os

from alphafence.errors import InputError

MAX_JSON_MB_DEFAULT = 512  # JSON is parsed whole: refuse what would not fit, before reading it


def max_json_bytes() -> int:
    """The largest JSON file read: ``$ALPHAFENCE_MAX_JSON_MB`` megabytes (default 512)."""
    return int(float(os.environ.get("ALPHAFENCE_MAX_JSON_MB", MAX_JSON_MB_DEFAULT)) * 1024 * 1024)


def read_limited(path, limit: int, too_big: str, unreadable: str = "cannot read") -> bytes:
    """The bytes of a file of at most ``limit`` bytes (only ``limit + 1`` are ever read).

    Raises
    ------
    InputError
        ``"<path>: <unreadable> (<why>)"`` when it cannot be read, ``"<path>: <too_big>"``
        when it is larger.
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise InputError(str(path), f"{unreadable} ({exc.strerror})") from None
    if len(data) > limit:
        raise InputError(str(path), too_big)
    return data


def read_json(path):
    """The parsed contents of a JSON file.

    Raises
    ------
    InputError
        A one-line message: no such file, larger than :func:`max_json_bytes`, not UTF-8, or
        malformed (with line and column).
    """
    try:
        size = os.path.getsize(path)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    limit = max_json_bytes()
    if size > limit:
        raise InputError(
            path,
            f"{size / 2**20:.0f} MB of JSON is more than the {limit / 2**20:.0f} MB limit "
            "(set ALPHAFENCE_MAX_JSON_MB to allow more, or use .osm.pbf, which is streamed)",
        )
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise InputError(
            path, f"malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
