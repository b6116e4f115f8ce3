"""Authenticated fence databases: a fence file plus its metadata, signed with Ed25519.

``sign`` writes a detached signature next to the fences (``FENCES.sig.json``): the SHA-256 of
the fence file, metadata (sources, rules, time, tool version) and an Ed25519 signature over
both, with the signer's public key. ``verify`` checks the file still has that digest, the
signature is valid, and the key is one the operator trusts. Nothing is trusted by default.
"""

from __future__ import annotations

import base64
import hashlib
import json
import time
from pathlib import Path

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from alphafence import __version__
from alphafence.errors import InputError
from alphafence.fencefiles.atomic import write_all

SUFFIX = ".sig.json"


def signature_path(fences) -> Path:
    """Where the signature of a fence file lives: beside it, ``.sig.json`` appended.

    Examples
    --------
    >>> signature_path("out/fences.geojson").as_posix()
    'out/fences.geojson.sig.json'
    """
    return Path(str(fences) + SUFFIX)


def generate_key(private_path, public_path):
    """Make an Ed25519 key pair: the private key (PKCS#8 PEM, mode 0600) and the public key
    (SubjectPublicKeyInfo PEM), written all or nothing."""
    key = Ed25519PrivateKey.generate()
    priv = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    ).decode()
    pub = (
        key.public_key()
        .public_bytes(serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo)
        .decode()
    )
    write_all({private_path: priv, public_path: pub})
    Path(private_path).chmod(0o600)


def _load(path, private):
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read key ({exc.strerror})") from None
    try:
        key = (
            serialization.load_pem_private_key(data, None)
            if private
            else serialization.load_pem_public_key(data)
        )
    except (ValueError, TypeError) as exc:
        raise InputError(
            path, f"not a PEM {'private' if private else 'public'} key ({exc})"
        ) from None
    want = Ed25519PrivateKey if private else Ed25519PublicKey
    if not isinstance(key, want):
        raise InputError(path, "not an Ed25519 key")
    return key


def check_private_key(path) -> None:
    """Refuse a signing key that :func:`sign` could not use, before anything is written.

    Raises
    ------
    InputError
        The key cannot be read or is not an Ed25519 private key (PEM).
    """
    _load(path, private=True)


def _raw(pub: Ed25519PublicKey) -> str:
    return pub.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw).hex()


def _digest(path) -> str:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    return h.hexdigest()


def _payload(body: dict) -> bytes:
    return json.dumps(body, sort_keys=True, separators=(",", ":")).encode()


def _metadata(fences) -> dict:
    meta = {
        "tool": f"alphafence {__version__}",
        "signed_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    try:
        doc = json.loads(Path(fences).read_text(encoding="utf-8"))
        build = doc.get("alphafence") if isinstance(doc, dict) else None
        if isinstance(build, dict):
            meta["build"] = build  # inputs, rules, method, ... as the build recorded them
    except (OSError, ValueError):
        pass
    return meta


def sign(fences, private_key_path) -> Path:
    """Sign a fence file: write its detached signature (:func:`signature_path`).

    The signature covers the file's SHA-256 and metadata (tool, time, and the build's
    inputs and options as the fence file records them).

    Returns
    -------
    Path
        The signature file.

    Raises
    ------
    InputError
        The key cannot be read or is not an Ed25519 private key; the fences cannot be read.
    """
    key = _load(private_key_path, private=True)
    body = {"file": Path(fences).name, "sha256": _digest(fences), "metadata": _metadata(fences)}
    sig = key.sign(_payload(body))
    doc = {
        **body,
        "algorithm": "ed25519",
        "public_key": _raw(key.public_key()),
        "signature": base64.b64encode(sig).decode(),
    }
    out = signature_path(fences)
    write_all({out: json.dumps(doc, indent=2) + "\n"})
    return out


def verify(fences, trusted_keys) -> dict:
    """The signed metadata, or InputError saying why the bundle is not authentic.

    Parameters
    ----------
    fences : str or Path
        The fence file; its signature is read from :func:`signature_path`.
    trusted_keys : sequence of str or Path
        PEM public keys the operator trusts (at least one).

    Returns
    -------
    dict
        The metadata that was signed.

    Raises
    ------
    InputError
        Not signed, malformed signature file, no trusted key given, signed by an untrusted
        key, signature invalid, or the fences changed since.
    """
    sig_path = signature_path(fences)
    if not sig_path.is_file():
        raise InputError(fences, f"not signed (no {sig_path.name})")
    try:
        doc = json.loads(sig_path.read_text(encoding="utf-8"))
        body = {k: doc[k] for k in ("file", "sha256", "metadata")}
        signature = base64.b64decode(doc["signature"], validate=True)
        signer = Ed25519PublicKey.from_public_bytes(bytes.fromhex(doc["public_key"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(sig_path, f"malformed signature file ({exc})") from None
    trusted = {_raw(_load(p, private=False)) for p in trusted_keys}
    if not trusted:
        raise InputError(fences, "no trusted public key given to verify against")
    if _raw(signer) not in trusted:
        raise InputError(fences, "signed with a key that is not trusted")
    try:
        signer.verify(signature, _payload(body))
    except InvalidSignature:
        raise InputError(sig_path, "signature does not match its contents (tampered?)") from None
    if body["sha256"] != _digest(fences):
        raise InputError(fences, "the fences changed after they were signed")
    return body["metadata"]
