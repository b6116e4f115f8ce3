"""alphafence update: apply OpenStreetMap's changes to fences built with ``--store``."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from alphafence.cli.common import err_console, out_console
from alphafence.errors import InputError, need


def register(sub):
    """Add the ``update`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "update",
        help="apply OpenStreetMap changes to fences built with --store",
        description="Rebuild only the sites that OpenStreetMap change files touch (a feature "
        "added, changed or deleted, a node moved, a relation's members changed), giving the "
        "fences a whole build of the changed extract gives. The fence file is rewritten beside "
        "and moved over, a PostGIS table changed in one transaction at its next version; on "
        "any failure, or Ctrl-C, the fences and the store stay as they were.",
    )
    p.add_argument("changes", nargs="*", metavar="CHANGES.osc.gz",
                   help="change files, in the order they apply (as pyosmium-get-changes "
                   "or osmium derive-changes write them)")  # fmt: skip
    p.add_argument("--store", required=True, metavar="FILE.sqlite",
                   help="the store the build kept (alphafence build --store)")  # fmt: skip
    p.add_argument("-o", "--output", metavar="FENCES",
                   help="the fences to update (default: the build's output, as the store "
                   "names it): a fence file or postgresql://.../SCHEMA.TABLE")  # fmt: skip
    p.add_argument("--replication", metavar="URL",
                   help="also fetch the changes since --state from this replication server "
                   "(e.g. https://planet.openstreetmap.org/replication/minute/)")  # fmt: skip
    p.add_argument("--state", metavar="FILE",
                   help="the replication sequence applied last (pyosmium-get-changes' state "
                   "file: one number); moved on once the update is written")  # fmt: skip
    p.add_argument("--max-diffs", type=int, default=60, metavar="N",
                   help="replication files fetched at most per run (default 60)")  # fmt: skip
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or summary")
    p.set_defaults(func=run)


def run(args) -> int:
    """Fetch (with ``--replication``), update, report; exit status 0."""
    import tempfile

    from alphafence.updating.update import update

    if bool(args.replication) != bool(args.state):
        raise InputError("update", "--replication and --state go together")
    if not args.changes and not args.replication:
        raise InputError("update", "give change files, or --replication URL --state FILE")
    need(("osmium.filter", "reading OpenStreetMap changes"))
    with tempfile.TemporaryDirectory(prefix="alphafence-diffs-") as tmp:
        files, sequence = list(args.changes), None
        if args.replication:
            fetched, sequence = fetch_diffs(args.replication, args.state, tmp, args.max_diffs)
            files += fetched
            if not files:
                if not args.quiet:
                    out_console.print(f"up to date at sequence {sequence}")
                return 0
        tty = not args.quiet and sys.stderr.isatty()  # steps said as they start, on a terminal
        say = (lambda s: err_console.print(f"[dim]{s}...[/dim]")) if tty else None
        result = update(args.store, files, args.output, progress=say)
    if sequence is not None:
        write_state(args.state, sequence)
    if not args.quiet:
        out_console.print(
            f"{result.changes} changed objects, {result.touched} read again: "
            f"{result.removed_features} restricted features out, {result.added_features} in; "
            f"{len(result.sites_removed)} sites' fences replaced by {len(result.sites_added)} "
            f"({result.rows_removed} rows out, {result.rows_added} in"
            + (f", version {result.version}" if result.version is not None else "")
            + f") in {result.seconds['total']:.2f} s"
        )
    return 0


def read_state(path) -> int:
    """The sequence number in a state file (a number, or ``sequenceNumber=N`` as a
    replication server's state.txt has it)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, f"cannot read the state file: {exc.strerror}") from None
    for line in text.splitlines():
        value = line.split("=", 1)[-1].strip()
        if value.isdigit():
            return int(value)
    raise InputError(path, "no sequence number in the state file")


def write_state(path, sequence):
    """Write the state file beside and move it over."""
    tmp = f"{path}.tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(f"{sequence}\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def fetch_diffs(url, state, folder, most) -> tuple:
    """The replication files after the state file's sequence (at most ``most``), downloaded
    into ``folder`` with pyosmium's ReplicationServer: ``(paths, last sequence)``."""
    from osmium.replication.server import ReplicationServer

    start = read_state(state)
    paths = []
    with ReplicationServer(url) as server:
        info = server.get_state_info()
        if info is None:
            raise InputError(url, "no replication state there (state.txt)")
        last = min(info.sequence, start + most)
        for seq in range(start + 1, last + 1):
            try:
                with server.open_url(server.make_request(server.get_diff_url(seq))) as resp:
                    # requests' Response (pyosmium 4) or urllib's (older releases)
                    status = getattr(resp, "status_code", None) or getattr(resp, "status", 200)
                    if status >= 400:
                        raise OSError(f"HTTP {status}")
                    data = resp.content if hasattr(resp, "content") else resp.read()
            except Exception as exc:  # noqa: BLE001 - urllib's and requests' errors alike
                raise InputError(url, f"replication file {seq} not fetched ({exc})") from None
            path = Path(folder) / f"{seq:09d}.osc.gz"
            path.write_bytes(data)
            paths.append(str(path))
    return paths, max(start, last)
