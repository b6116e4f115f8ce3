"""alphafence compare: the paper's evaluation of fence methods on a database."""

from __future__ import annotations

import json

from alphafence.cli.common import callback, out_console, progress
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.source_options import add_database_options, build_options, build_wants
from alphafence.cli.tables import stats_table
from alphafence.errors import InputError, need
from alphafence.fencing import METHODS


def register(sub):
    """Add the ``compare`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "compare",
        help="compare fence methods (containment, overshoot, vertices, time)",
        description="Compare alpha-shape fences with polygonal, circular and exact fences.",
    )
    add_database_options(p)
    p.add_argument(
        "--methods",
        type=methods,
        default=list(METHODS),
        metavar="LIST",
        help="comma-separated methods (default alpha,polygon,circle,exact)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument(
        "--figure", metavar="OUT.png", help="draw the methods side by side on telling sites"
    )
    add_map_options(p)
    p.set_defaults(func=run)


def methods(text):
    """argparse type: comma-separated fence methods -> a list; unknown ones are an InputError.

    Examples
    --------
    >>> methods("alpha, circle")
    ['alpha', 'circle']
    """
    chosen = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in chosen if m not in METHODS]
    if bad or not chosen:
        raise InputError(
            "--methods",
            f"unknown method(s) {', '.join(bad) or '(none)'}; choose from {', '.join(METHODS)}",
        )
    return chosen


def run(args) -> int:
    """Build fences with each method and print (or, with --json, dump) how they compare."""
    from alphafence.fencing.compare import compare_methods, telling_sites
    from alphafence.fencing.outputs import OSM_ATTRIBUTION
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    need(*build_wants(args.databases, args.figure))
    check_map_args(args)
    rules = load_rules(args.rules)
    opts = build_options(args)
    with progress(not args.json) as prog:
        db = read_database(args.databases, rules, args.bbox, bbox_name="--bbox")
        cmp = compare_methods(
            db.features, rules, args.methods, opts, progress=callback(prog, "building fences")
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
    osm = any(".osm" in f or f.endswith(".pbf") for f in db.files)
    if args.map:
        from alphafence.cli.maps import write_map_page
        from alphafence.plots.webmap import method_layers, restricted_layer

        layers = [restricted_layer(cmp.sites), *method_layers(cmp.fences)]
        title = f"AlphaFence: {', '.join(args.methods)} fences of {len(cmp.sites)} sites"
        write_map_page(args, title, layers, note=OSM_ATTRIBUTION if osm else None)
        if not args.json:
            out_console.print(f"wrote {args.map}")
    if args.figure:
        from alphafence.plots.compare import comparison_figure

        comparison_figure(
            telling_sites(cmp), cmp.fences, args.figure, note=OSM_ATTRIBUTION if osm else None
        )
        if not args.json:
            out_console.print(f"wrote {args.figure}")
    return 0
