"""The ``alphafence`` command: one verb per module, each a thin layer over the library.

Each verb module has ``register(sub)``, which adds its sub-parser, and ``run(args)``, which
calls the library and returns the exit status. Verbs import the library and the shared
modules :mod:`~alphafence.cli.options` (argument types, option groups),
:mod:`~alphafence.cli.common` (consoles, progress, trust) and :mod:`~alphafence.cli.tables`,
never another verb. :func:`main` turns the library's errors into one line on stderr and the
error's exit status.
"""

from __future__ import annotations

import sys

from alphafence import __version__
from alphafence.errors import AlphaFenceError, missing_dependency

# in the order of the workflow (get data -> build -> compile / upload --dry-run -> upload ->
# monitor -> check-flight), then planning, signing and trying out; --help lists them so
VERBS = (
    "build",
    "update",
    "compare",
    "compile",
    "upload",
    "download",
    "monitor",
    "check-flight",
    "route",
    "check-mission",
    "bundle",
    "signing",
    "sitl",
    "demo",
)

EPILOG = """\
the workflow:
  1. get map data for your area (an OpenStreetMap extract, a geozone list)
  2. alphafence build AREA.osm.pbf -o fences.geojson
     (kept current: build ... --store STORE, then alphafence update CHANGES.osc.gz --store STORE)
  3. alphafence upload fences.geojson --bbox MINLON,MINLAT,MAXLON,MAXLAT --dry-run
  4. alphafence upload fences.geojson --bbox ... --connect /dev/ttyACM0
  5. alphafence monitor --fences fences.geojson --connect udpin:0.0.0.0:14550
  6. alphafence check-flight FLIGHT.tlog --fences fences.geojson
'alphafence VERB --help' says more about each verb. The docs: docs/index.md in the
AlphaFence checkout (browse them with 'mkdocs serve')."""


def parser(verb=None):
    """The ``alphafence`` argument parser, with one sub-parser per verb in :data:`VERBS`.

    Parameters
    ----------
    verb : str, optional
        Register only this verb's sub-parser (when it is one of :data:`VERBS`): a run of one
        verb imports no other verb's modules.

    Returns
    -------
    alphafence.cli.options.Parser
        Parsed arguments carry ``verb`` and ``func``, the verb's ``run``.
    """
    import argparse
    import importlib

    from alphafence.cli.common import DefaultsFormatter
    from alphafence.cli.options import Parser

    class Formatter(DefaultsFormatter, argparse.RawDescriptionHelpFormatter):
        """The workflow in the epilog keeps its lines; each verb's summary on its line."""

        def add_argument(self, action):
            super().add_argument(action)
            if isinstance(action, argparse._SubParsersAction):  # listed 2 columns further in
                self._action_max_length += 2

    p = Parser(
        prog="alphafence",
        description="Tight, safe alpha-shape geofences for ArduPilot vehicles.",
        epilog=EPILOG,
        formatter_class=Formatter,
    )
    p.add_argument("--version", action="version", version=f"alphafence {__version__}")
    sub = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    for name in (verb,) if verb in VERBS else VERBS:
        importlib.import_module(f"alphafence.cli.{name.replace('-', '_')}").register(sub)
    return p


def main(argv=None) -> int:
    """Run the ``alphafence`` command line.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status: the verb's own (0, or 1 for ``check-mission``'s crossing legs), the
        ``exit_code`` of an :class:`~alphafence.errors.AlphaFenceError` (2 for bad input or a
        missing optional package, 3 when the vehicle or its link fails, 1 otherwise), or 130
        on Ctrl-C. A usage error
        exits (``SystemExit``) with status 2, as argparse does.

    Examples
    --------
    >>> main(["route", "fences.geojson", "--from", "95,14", "--to", "0,0", "-o", "m.plan"])
    2
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    args = None
    try:
        args = parser(_verb(argv)).parse_args(argv)
        return int(args.func(args) or 0)
    except AlphaFenceError as exc:
        verb = args.verb if args is not None else _verb(argv)
        print(f"alphafence {verb}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except ImportError as exc:  # an optional package a verb did not check for first
        verb = args.verb if args is not None else _verb(argv)
        missing = missing_dependency(exc, verb)
        if missing is None:
            raise
        print(f"alphafence {verb}: error: {missing}", file=sys.stderr)
        return missing.exit_code
    except KeyboardInterrupt:
        print("alphafence: interrupted", file=sys.stderr)
        return 130


def _verb(argv):
    # an error raised while parsing (by an argument type): the verb is the first word, as the
    # top-level parser has no option that takes a value
    return next((a for a in argv if not a.startswith("-")), "")
