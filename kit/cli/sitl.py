"""alphafence sitl: find (and, later, run) a user-built ArduPilot SITL binary."""

from __future__ import annotations

import sys

from kit.sitl.find import NOT_FOUND_HELP, find_sitl_binary


def register(sub):
    p = sub.add_parser(
        "sitl",
        help="ArduPilot SITL helpers",
        description="Find a user-built ArduPilot SITL binary.",
    )
    p.add_argument(
        "--find", action="store_true", help="print the arducopter binary found, or how to get one"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    found = find_sitl_binary()
    if found is None:
        print(NOT_FOUND_HELP, file=sys.stderr)
        return 1
    print(found)
    return 0
