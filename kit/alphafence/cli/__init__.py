"""The ``alphafence`` command: one verb per module, each a thin layer over the library."""

from __future__ import annotations

import argparse
import sys

from alphafence import __version__
from alphafence.errors import InputError

VERBS = (
    "build",
    "compare",
    "compile",
    "upload",
    "download",
    "monitor",
    "bundle",
    "signing",
    "demo",
    "sitl",
    "route",
    "check-mission",
)


def parser() -> argparse.ArgumentParser:
    import importlib

    p = argparse.ArgumentParser(
        prog="alphafence",
        description="Tight, safe alpha-shape geofences for ArduPilot vehicles.",
    )
    p.add_argument("--version", action="version", version=f"alphafence {__version__}")
    sub = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb in VERBS:
        importlib.import_module(f"alphafence.cli.{verb.replace('-', '_')}").register(sub)
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"alphafence {args.verb}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("alphafence: interrupted", file=sys.stderr)
        return 130
