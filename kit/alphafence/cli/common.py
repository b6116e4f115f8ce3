"""What the verbs share besides argument types: consoles, progress bars, the help formatter,
the fence-signature options and check, the MAVLink signing-key option and key."""

from __future__ import annotations

import argparse
import os
import sys
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)

from alphafence.errors import InputError, VehicleError

# what a build with several malformed zones ends with (each a zone --skip-invalid leaves out)
SKIP_HINT = "nothing was written; --skip-invalid leaves these zones out and builds the rest"


# piped or captured output gets a table-friendly width instead of rich's default 80 columns
class _Console(Console):
    """Rich's console; where it is not a terminal (a pipe, journald, a log file) a message
    is one line, never wrapped, and tables are drawn 120 columns wide."""

    def print(self, *objects, **kw):
        if not self.is_terminal and all(isinstance(o, str) for o in objects):
            kw.setdefault("soft_wrap", True)
        super().print(*objects, **kw)


err_console = _Console(stderr=True, width=None if sys.stderr.isatty() else 120)
out_console = _Console(width=None if sys.stdout.isatty() else 120)


class DefaultsFormatter(argparse.HelpFormatter):
    """argparse's help formatter, adding ``(default: X)`` to an option's help when it has a
    default worth saying (not None, False or an empty list) and its help does not already
    say one."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (
            not action.option_strings
            or action.default in (None, False, [], argparse.SUPPRESS)
            or "default" in text
        ):
            return text
        return f"{text} (default: %(default)s)"


class RateColumn(ProgressColumn):
    """Items per second of a task (rich's own speed columns count bytes)."""

    def render(self, task):
        """The task's rate, e.g. ``12,345/s`` (empty until rich has measured one)."""
        from rich.text import Text

        speed = task.finished_speed or task.speed
        return Text(f"{speed:,.0f}/s" if speed else "", style="progress.data.speed")


@contextmanager
def progress(enabled=True):
    """A transient rich progress bar on stderr, or ``None`` when disabled or not a terminal.

    Yields
    ------
    rich.progress.Progress or None
        Pass it to :func:`callback` to draw a task into it.
    """
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        RateColumn(),
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


def add_trust_options(p: argparse.ArgumentParser) -> None:
    """Add ``--trusted-key`` and ``--allow-unsigned``, which :func:`check_trust` reads."""
    p.add_argument(
        "--trusted-key",
        action="append",
        default=[],
        metavar="KEY.pub.pem",
        help="accept fences signed by this Ed25519 public key, from 'alphafence bundle "
        "keygen' (who made the fences; not the link's --signing-key); repeatable; also "
        "$ALPHAFENCE_TRUSTED_KEYS",
    )
    p.add_argument(
        "--allow-unsigned",
        action="store_true",
        help="use fences that are not signed by a trusted key (say so in the log)",
    )


def check_trust(args, path):
    """Verify the fences at ``path`` against the trusted keys (``--trusted-key`` and
    ``$ALPHAFENCE_TRUSTED_KEYS``).

    Returns
    -------
    dict or None
        The signature's metadata, or ``None`` for unverified fences used under
        ``--allow-unsigned`` (a warning is printed).

    Raises
    ------
    InputError
        ``path`` is a map database (an OSM extract: fences are built of it first), or the
        fences do not verify and ``--allow-unsigned`` was not given.
    """
    from alphafence.fencing.bundle import verify
    from alphafence.zones.mistakes import refuse_map_database

    refuse_map_database(path)  # said before its signature is looked for

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
            exc.message
            + "; sign them (alphafence bundle sign; a compiled plan: compile --sign-key) or "
            "pass --allow-unsigned",
            exc.feature,
        ) from None


def add_link_option(p: argparse.ArgumentParser) -> None:
    """Add ``--link`` (also ``$ALPHAFENCE_LINK``): which vehicle link to use."""
    p.add_argument(
        "--link",
        choices=("auto", "pymavlink", "mavsdk"),
        default=None,
        help="vehicle link: pymavlink (pure Python, any platform, a Navio2 included) or "
        "mavsdk (MAVSDK 4's native binding); auto takes what is installed (also "
        "$ALPHAFENCE_LINK)",
    )


def add_signing_option(p: argparse.ArgumentParser) -> None:
    """Add ``--signing-key``, which :func:`signing_key` reads."""
    p.add_argument(
        "--signing-key",
        metavar="FILE",
        default=None,
        help="MAVLink 2 link signing key file, from 'alphafence signing keygen' (who may "
        "talk to the vehicle; not the fences' --trusted-key): 64 hex digits or a passphrase; "
        "also $ALPHAFENCE_SIGNING_KEY: sign what is sent, accept only what is signed",
    )


def signing_key(args):
    """The 32-byte MAVLink signing key from --signing-key or $ALPHAFENCE_SIGNING_KEY (a file
    path), or None for an unsigned link."""
    from alphafence.vehicle.keys import key_file_warning, load_key

    path = args.signing_key or os.environ.get("ALPHAFENCE_SIGNING_KEY") or None
    if path is None:
        return None
    warning = key_file_warning(path)
    if warning:
        err_console.print(f"[yellow]warning:[/] {warning}", soft_wrap=True)
    return load_key(path)


@contextmanager
def unsigned_hint(key):
    """Add a hint to a vehicle error that timed out over an unsigned link (``key`` is None):
    the vehicle may be signing, and ignoring what it cannot verify."""
    try:
        yield
    except VehicleError as exc:
        if key or getattr(exc, "result", None) != "TIMEOUT":
            raise
        raise VehicleError(
            f"{exc} (if the vehicle has MAVLink signing on, give --signing-key)"
        ) from exc


def union_hint(items) -> None:
    """Print the note that fence items with more than one inclusion need ``FENCE_OPTIONS``
    bit 1 on the vehicle (:func:`alphafence.mavlink.inclusions.union_note`), if they do."""
    from alphafence.mavlink.inclusions import union_note

    note = union_note(items)
    if note:
        err_console.print(f"[yellow]note:[/] {note}", soft_wrap=True)
