"""Run the benchmarks and print each result against its target and its named peer.

python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf
python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf --only soak  # 30 min (make soak)
python -m bench --osm ../shared/data/osm/malta-2018-08-27.osm.pbf --only scale --scale-sizes 13300
"""

from __future__ import annotations

import argparse
import sys

from rich.console import Console
from rich.table import Table

from bench import (
    as_read_bench,
    build_bench,
    cli_bench,
    compile_bench,
    link_bench,
    livemap_bench,
    monitor_bench,
    monitor_cpu_bench,
    rolling_bench,
    route_bench,
    route_national_bench,
    scale_bench,
    soak_bench,
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
            "build",
            "cli",
            "compile",
            "upload",
            "monitor",
            "map",
            "rolling",
            "route",
            "scale",
            "soak",
        ],
        help="run one group (soak only runs when asked for: 30 minutes of SITL)",
    )
    p.add_argument(
        "--soak-minutes",
        type=float,
        default=30.0,
        metavar="N",
        help="wall minutes of the soak (default 30)",
    )
    p.add_argument(
        "--scale-sizes",
        type=lambda s: tuple(int(v) for v in s.split(",")),
        default=scale_bench.SIZES,
        metavar="N,N",
        help="areas built by the scale group (default 133000,1000000)",
    )
    args = p.parse_args(argv)
    console = Console(width=150)
    rows = []
    if args.only in (None, "as-read"):
        rows += as_read_bench.run(build_bench.Row)
    if args.only in (None, "build"):
        rows += build_bench.run(args.osm, args.optimize_sites, console)
    if args.only in (None, "cli"):
        rows += cli_bench.run(build_bench.Row)
    if args.only in (None, "compile"):
        rows += compile_bench.run(args.osm, build_bench.Row)
        rows += compile_bench.navio2(args.osm, build_bench.Row)
        rows += compile_bench.corridor(args.osm, build_bench.Row)
    if args.only in (None, "upload"):
        rows += upload_bench.run(build_bench.Row)
    if args.only in (None, "monitor"):
        rows += monitor_bench.run(args.osm, build_bench.Row)
        rows += monitor_cpu_bench.run(args.osm, build_bench.Row)
        rows += link_bench.run(build_bench.Row)
    if args.only in (None, "map"):
        rows += livemap_bench.run(args.osm, build_bench.Row)
    if args.only in (None, "rolling"):
        rows += rolling_bench.overshoot(args.osm, build_bench.Row)
        rows += rolling_bench.in_flight(args.osm, build_bench.Row)
    if args.only in (None, "route"):
        rows += route_bench.run(args.osm, build_bench.Row)
        rows += route_national_bench.run(build_bench.Row)
    if args.only in (None, "scale"):
        rows += scale_bench.run(args.osm, build_bench.Row, console, args.scale_sizes)
    if args.only == "soak":
        rows += soak_bench.run(args.osm, build_bench.Row, args.soak_minutes, console)
    elif args.only is None:  # too long for the default run
        rows.append(
            build_bench.Row(
                "soak: monitor on SITL x10 with ADS-B, 30 min",
                "not run: `make soak`",
                "no missed check, 0 exceptions, < 20 MB",
                "-",
                "-",
                True,
            )
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
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
