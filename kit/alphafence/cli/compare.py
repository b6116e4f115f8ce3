"""alphafence compare: the paper's evaluation of fence methods on a database."""

from __future__ import annotations

import json

from rich.table import Table

from alphafence.build.compare import compare_methods, telling_sites
from alphafence.build.fences import METHODS
from alphafence.build.outputs import OSM_ATTRIBUTION
from alphafence.cli.build import options_from
from alphafence.cli.common import add_database_options, callback, out_console, progress
from alphafence.errors import InputError
from alphafence.formats.database import read_database
from alphafence.formats.rules import load_rules


def register(sub):
    p = sub.add_parser(
        "compare",
        help="compare fence methods (containment, overshoot, vertices, time)",
        description="Compare alpha-shape fences with polygonal, circular and exact fences.",
    )
    add_database_options(p)
    p.add_argument(
        "--methods",
        default="alpha,polygon,circle,exact",
        metavar="LIST",
        help="comma-separated methods (default alpha,polygon,circle,exact)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument(
        "--figure", metavar="OUT.png", help="draw the methods side by side on telling sites"
    )
    p.set_defaults(func=run)


def parse_methods(text):
    methods = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise InputError(
            "--methods",
            f"unknown method(s) {', '.join(bad) or '(none)'}; choose from {', '.join(METHODS)}",
        )
    return methods


def run(args) -> int:
    methods = parse_methods(args.methods)
    rules = load_rules(args.rules)
    opts = options_from(args)
    with progress(not args.json) as prog:
        db = read_database(args.databases, rules, args.bbox)
        cmp = compare_methods(
            db.features, rules, methods, opts, progress=callback(prog, "building fences")
        )
    if args.json:
        print(
            json.dumps(
                {
                    "inputs": db.files,
                    "margin_override_m": opts.margin_m,
                    "methods": [s.as_dict() for s in cmp.stats],
                },
                indent=2,
            )
        )
    else:
        out_console.print(stats_table(cmp, opts))
    if args.figure:
        from alphafence.plots.compare import comparison_figure

        osm = any(".osm" in f or f.endswith(".pbf") for f in db.files)
        comparison_figure(
            telling_sites(cmp), cmp.fences, args.figure, note=OSM_ATTRIBUTION if osm else None
        )
        if not args.json:
            out_console.print(f"wrote {args.figure}")
    return 0


def stats_table(cmp, opts) -> Table:
    margin = "rules' margins" if opts.margin_m is None else f"margin {opts.margin_m:g} m"
    t = Table(title=f"{cmp.stats[0].sites} sites, {margin}")
    for col in (
        "method",
        "contain %",
        "overshoot",
        "excess",
        "v median",
        "v p95",
        "v total",
        "time s",
    ):
        t.add_column(col, justify="left" if col == "method" else "right")
    for s in cmp.stats:
        t.add_row(
            s.method,
            f"{s.containment_pct:.2f}",
            f"{s.overshoot:.3f}",
            f"{s.excess:.3f}",
            f"{s.vertices_median:.0f}",
            f"{s.vertices_p95:.0f}",
            str(s.vertices_total),
            f"{s.seconds:.2f}",
        )
    return t
