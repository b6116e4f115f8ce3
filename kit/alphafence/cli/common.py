"""Options and output helpers shared by the verbs."""

from __future__ import annotations

import sys
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)

from alphafence.formats.features import parse_bbox

# piped or captured output gets a table-friendly width instead of rich's default 80 columns
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 120)
out_console = Console(width=None if sys.stdout.isatty() else 120)


def add_database_options(p):
    p.add_argument(
        "databases",
        nargs="+",
        metavar="DATABASE",
        help="geofence database(s): .osm.pbf, .osm, GeoJSON or ED-269 JSON",
    )
    p.add_argument("--rules", metavar="FILE", help="rules TOML (default: the shipped rules)")
    p.add_argument(
        "--bbox",
        metavar="MINLON,MINLAT,MAXLON,MAXLAT",
        type=_bbox,
        help="only features intersecting this box",
    )
    p.add_argument(
        "--join",
        type=float,
        default=25.0,
        metavar="M",
        help="features of one category within M metres form one site (default 25)",
    )
    p.add_argument(
        "--margin",
        type=float,
        default=None,
        metavar="M",
        help="override every rule's margin (0 = the paper's setting)",
    )
    p.add_argument(
        "--max-vertices",
        type=int,
        default=32,
        metavar="N",
        help="vertex budget per fence polygon (default 32)",
    )


def _bbox(text):
    from alphafence.errors import InputError

    try:
        return parse_bbox(text)
    except InputError as exc:
        import argparse

        raise argparse.ArgumentTypeError(exc.message) from None


@contextmanager
def progress(enabled=True):
    """A rich progress bar on stderr (transient); yields a task factory."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    ) as prog:
        yield prog


def callback(prog, description):
    """A ``progress(done, total)`` callback drawing into ``prog`` (or None)."""
    if prog is None:
        return None
    task = prog.add_task(description, total=None)

    def update(done, total):
        prog.update(task, completed=done, total=total)

    return update


def add_trust_options(p):
    p.add_argument(
        "--trusted-key",
        action="append",
        default=[],
        metavar="KEY.pub.pem",
        help="accept fences signed by this Ed25519 key (repeatable; also $ALPHAFENCE_TRUSTED_KEYS)",
    )
    p.add_argument(
        "--allow-unsigned",
        action="store_true",
        help="use fences that are not signed by a trusted key (say so in the log)",
    )


def check_trust(args, path):
    """Refuse fences that do not verify against a trusted key, unless --allow-unsigned."""
    import os

    from alphafence.build.bundle import verify
    from alphafence.errors import InputError

    keys = list(args.trusted_key) + [
        k for k in os.environ.get("ALPHAFENCE_TRUSTED_KEYS", "").split(os.pathsep) if k
    ]
    try:
        if not keys:
            raise InputError(path, "no trusted key to verify the fences against (--trusted-key)")
        return verify(path, keys)
    except InputError as exc:
        if args.allow_unsigned:
            err_console.print(f"[yellow]warning:[/] using unverified fences: {exc}", soft_wrap=True)
            return None
        raise InputError(
            exc.path,
            exc.message + "; sign them (alphafence bundle sign) or pass --allow-unsigned",
            exc.feature,
        ) from None


def add_signing_option(p):
    p.add_argument(
        "--signing-key",
        metavar="FILE",
        default=None,
        help="MAVLink 2 signing key file (64 hex digits or a passphrase; also "
        "$ALPHAFENCE_SIGNING_KEY): sign what is sent, accept only what is signed",
    )


def signing_key(args):
    """The 32-byte MAVLink signing key from --signing-key or $ALPHAFENCE_SIGNING_KEY (a file
    path), or None for an unsigned link."""
    import os

    from alphafence.vehicle.keys import key_file_warning, load_key

    path = args.signing_key or os.environ.get("ALPHAFENCE_SIGNING_KEY") or None
    if path is None:
        return None
    warning = key_file_warning(path)
    if warning:
        err_console.print(f"[yellow]warning:[/] {warning}", soft_wrap=True)
    return load_key(path)


def unsigned_hint(args, exc) -> str:
    """A hint after a transfer over an unsigned link timed out: the vehicle may be signing."""
    signed = getattr(args, "key", None) or getattr(args, "signing_key", None)
    if signed or getattr(exc, "result", None) != "TIMEOUT":
        return ""
    return " (if the vehicle has MAVLink signing on, give --signing-key)"
