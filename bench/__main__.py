"""Run the benchmarks and print each result against its target and its named peer.

python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf
python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf --only soak  # 30 min (make soak)
python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf --only scale --scale-sizes 13300

Besides the table, the rows are written as JSON to ``--out``/results.json (default
``bench-out/``): ``{"created", "argv", "cores", "loadavg": [at start, at end], "rows": [...]}``,
each row ``{"group", "name", "result", "value", "unit", "target", "peer", "peer_value",
"ratio", "ok"}`` (``value`` and ``peer_value`` numbers in ``unit``, or null where a row has
none; ``ratio`` as the table shows it, null for "-").
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import sys

from rich.console import Console
from rich.table import Table

from bench import (
    as_read_bench,
    baseline_bench,
    build_bench,
    cli_bench,
    compile_bench,
    link_bench,
    live_bench,
    livemap_bench,
    monitor_bench,
    monitor_cpu_bench,
    planet_bench,
    rolling_bench,
    route_bench,
    route_national_bench,
    scale_bench,
    soak_bench,
    source_budget_bench,
    update_bench,
    upload_bench,
)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench")
    p.add_argument("--osm", required=True, help="OSM extract (Malta)")
    p.add_argument(
        "--optimize-sites",
        type=int,
        default=8,
        help="sites timed against alphashape.optimizealpha (it is slow)",
    )
    p.add_argument(
        "--only",
        choices=[
            "as-read",
            "as-read-cost",
            "build",
            "cli",
            "compile",
            "upload",
            "monitor",
            "map",
            "live",
            "source-budget",
            "rolling",
            "route",
            "scale",
            "update",
            "baseline",
            "planet",
            "soak",
        ],
        help="run one group (soak only runs when asked for: 30 minutes of SITL)",
    )
    p.add_argument(
        "--out",
        default="bench-out",
        metavar="DIR",
        help="folder of results.json, the rows as JSON (default bench-out)",
    )
    p.add_argument(
        "--soak-minutes",
        type=float,
        default=30.0,
        metavar="N",
        help="wall minutes of the soak (default 30)",
    )
    for group, default, what in (
        ("scale", scale_bench.SIZES, "areas built by the scale group (default 133000,1000000)"),
        ("update", update_bench.SIZES, "areas of the update group's extracts (default 133000; "
         "1000000 for its target)"),
        ("planet", planet_bench.SIZES, "areas of the planet group's builds (default "
         "1000000,2000000)"),
    ):  # fmt: skip
        p.add_argument(f"--{group}-sizes", type=_sizes, default=default, metavar="N,N", help=what)
    args = p.parse_args(argv)
    _use_shared_sitl()
    console = Console(width=150)
    rows = []
    load_start = _loadavg()

    def take(group, new):
        for r in new:
            r.group = r.group or group
        rows.extend(new)

    if args.only in (None, "as-read"):
        take("as-read", as_read_bench.run(build_bench.Row))
    if args.only in (None, "as-read-cost"):
        take("as-read-cost", as_read_bench.cost(args.osm, build_bench.Row, console))
    if args.only in (None, "build"):
        take("build", build_bench.run(args.osm, args.optimize_sites, console))
    if args.only in (None, "cli"):
        take("cli", cli_bench.run(build_bench.Row, args.osm))
    if args.only in (None, "compile"):
        take("compile", compile_bench.run(args.osm, build_bench.Row))
        take("compile", compile_bench.navio2(args.osm, build_bench.Row))
        take("compile", compile_bench.corridor(args.osm, build_bench.Row))
    if args.only in (None, "upload"):
        take("upload", upload_bench.run(build_bench.Row))
    if args.only in (None, "monitor"):
        take("monitor", monitor_bench.run(args.osm, build_bench.Row))
        take("monitor_cpu", monitor_cpu_bench.run(args.osm, build_bench.Row))
        take("link", link_bench.run(build_bench.Row))
    if args.only in (None, "map"):
        take("map", livemap_bench.run(args.osm, build_bench.Row))
    if args.only in (None, "live"):
        take("live", live_bench.run(args.osm, build_bench.Row))
    if args.only in (None, "source-budget"):
        take("source-budget", source_budget_bench.run(build_bench.Row))
    if args.only in (None, "rolling"):
        take("rolling", rolling_bench.overshoot(args.osm, build_bench.Row))
        take("rolling", rolling_bench.in_flight(args.osm, build_bench.Row))
    if args.only in (None, "route"):
        take("route", route_bench.run(args.osm, build_bench.Row))
        take("route", route_national_bench.run(build_bench.Row))
    if args.only in (None, "scale"):
        take("scale", scale_bench.run(args.osm, build_bench.Row, console, args.scale_sizes))
    if args.only in (None, "baseline"):
        take("baseline", baseline_bench.run(args.osm, build_bench.Row, console))
    if args.only in (None, "update"):
        take("update", update_bench.run(args.osm, build_bench.Row, console, args.update_sizes))
    if args.only == "planet":  # too long for the default run
        take("planet", planet_bench.run(args.osm, build_bench.Row, console, args.planet_sizes))
    if args.only == "soak":
        take("soak", soak_bench.run(args.osm, build_bench.Row, args.soak_minutes, console))
    elif args.only is None:  # too long for the default run
        take(
            "soak",
            [
                build_bench.Row(
                    "soak: monitor on SITL x10 with ADS-B, 30 min",
                    "not run: `make soak`",
                    "no missed check, 0 exceptions, < 20 MB",
                    "-",
                    "-",
                    True,
                )
            ],
        )
    table = Table(title="AlphaFence benchmarks (this machine, one run)")
    for col in ("benchmark", "result", "target", "peer", "ratio", "ok"):
        table.add_column(col, justify="left" if col in ("benchmark", "peer") else "right")
    failed = 0
    for r in rows:
        failed += not r.ok
        table.add_row(
            r.name, r.result, r.target, r.peer, r.ratio, "[green]yes[/]" if r.ok else "[red]NO[/]"
        )
    console.print(table)
    path = write_results(args.out, rows, argv, load_start)
    console.print(f"rows written to {path}")
    return 1 if failed else 0


def _sizes(text):
    """``--X-sizes``: areas, comma-separated."""
    return tuple(int(v) for v in text.split(","))


def _use_shared_sitl():
    """The copter SITL beside the checkout (``../shared/ardupilot-sitl``) when no other is
    found ($ARDUPILOT_SITL, $ARDUPILOT_HOME, ~/ardupilot, PATH), as the tests use it."""
    from pathlib import Path

    from alphafence.sitl.find import find_sitl_binary

    shared = Path(__file__).resolve().parents[2] / "shared" / "ardupilot-sitl"
    if find_sitl_binary() is None and (shared / "build/sitl/bin/arducopter").is_file():
        os.environ["ARDUPILOT_HOME"] = str(shared)


def _loadavg():
    try:
        return list(os.getloadavg())
    except OSError:
        return None


def _number(x):
    """A finite float, or None (JSON has no NaN or infinity)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def results(rows, argv=None, load_start=None) -> dict:
    """The rows as the JSON document ``results.json`` holds (see the module's docstring)."""
    out = []
    for r in rows:
        row = dataclasses.asdict(r)
        ratio = row["ratio"]
        out.append(
            {
                "group": row["group"],
                "name": row["name"],
                "result": row["result"],
                "value": _number(row["value"]),
                "unit": row["unit"] or None,
                "target": row["target"],
                "peer": None if row["peer"] == "-" else row["peer"],
                "peer_value": _number(row["peer_value"]),
                "ratio": None if ratio == "-" else ratio,
                "ok": bool(row["ok"]),
            }
        )
    return {
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "argv": list(sys.argv[1:] if argv is None else argv),
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "loadavg": [load_start, _loadavg()],
        "rows": out,
    }


def write_results(folder, rows, argv=None, load_start=None):
    """Write ``folder``/results.json atomically (all of it or nothing); returns its path."""
    from alphafence.fencefiles.atomic import write_all

    path = os.path.join(folder, "results.json")
    doc = results(rows, argv, load_start)
    write_all({path: json.dumps(doc, indent=1, allow_nan=False) + "\n"})
    return path


if __name__ == "__main__":
    sys.exit(main())
