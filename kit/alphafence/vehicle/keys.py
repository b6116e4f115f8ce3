"""MAVLink 2 signing keys: key files, passphrase keys and signing timestamps.

A key is 32 bytes. A key file holds either the key as 64 hexadecimal digits (what
``alphafence signing keygen`` writes, mode 0600) or a passphrase, whose SHA-256 is the key, as
MAVProxy's ``signing setup PASSPHRASE`` computes it, so a vehicle set up with MAVProxy works
with the same passphrase here.

Both the signed link (:mod:`alphafence.vehicle.bridge`) and installing a key on a vehicle
(:mod:`alphafence.vehicle.signing`) build on this module; it imports neither.
"""

from __future__ import annotations

import hashlib
import os
import re
import stat
import time
from pathlib import Path

from alphafence.errors import InputError
from alphafence.zones.jsonfile import read_limited

KEY_BYTES = 32
MAX_KEY_FILE_BYTES = 4096
EPOCH_2015 = 1420070400  # 2015-01-01T00:00:00Z: MAVLink signing timestamps count from here
_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}")


def load_key(path: str | os.PathLike) -> bytes:
    """The 32-byte key in a key file (64 hex digits, or a passphrase hashed with SHA-256)."""
    p = Path(path)
    data = read_limited(
        p, MAX_KEY_FILE_BYTES, "not a signing key file (over 4 KB)", "cannot read the signing key"
    )
    try:
        text = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise InputError(
            str(path), "not a signing key file (not UTF-8 text: 64 hex digits or a passphrase)"
        ) from None
    if not text:
        raise InputError(str(path), "the signing key file is empty")
    if "\n" in text:
        raise InputError(str(path), "a signing key file holds one line (a key or a passphrase)")
    if _HEX_KEY.fullmatch(text):
        key = bytes.fromhex(text)
    else:
        key = hashlib.sha256(text.encode("utf-8")).digest()
    if key == bytes(KEY_BYTES):
        raise InputError(str(path), "an all-zero key switches signing off; it cannot sign")
    return key


def key_file_warning(path: str | os.PathLike) -> str | None:
    """A warning when others than the owner may read the key file (None when private)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        return f"{path}: the signing key is readable by others (chmod 600 {path})"
    return None


def write_new_key(path: str | os.PathLike) -> bytes:
    """Write a fresh random key as 64 hex digits to a new file, mode 0600; refuse to
    overwrite an existing file (a vehicle may already hold that key)."""
    p = Path(path)
    key = os.urandom(KEY_BYTES)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise InputError(str(path), f"cannot write the key: {exc.strerror}") from None
    try:
        with os.fdopen(fd, "w") as f:
            f.write(key.hex() + "\n")
            f.flush()
            os.fsync(f.fileno())
        try:
            os.link(tmp, p)  # atomic, and fails if the file exists
        except FileExistsError:
            raise InputError(
                str(path), "exists already; refusing to overwrite a signing key"
            ) from None
        except OSError as exc:
            raise InputError(str(path), f"cannot write the key: {exc.strerror}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return key


def signing_timestamp(now: float | None = None) -> int:
    """The MAVLink signing timestamp: units of 10 microseconds since 2015-01-01 UTC."""
    now = time.time() if now is None else now
    return max(0, int((now - EPOCH_2015) * 100_000))


def key_id(key: bytes) -> str:
    """A short fingerprint to name a key in messages (never the key itself)."""
    return hashlib.sha256(b"alphafence-key-id" + key).hexdigest()[:8]
