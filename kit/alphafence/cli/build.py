"""alphafence build: read a geofence database, group sites, write fences."""

from __future__ import annotations

from collections import Counter, defaultdict

from rich.table import Table

from alphafence.build import METHODS
from alphafence.cli.common import callback, err_console, out_console, progress
from alphafence.cli.options import (
    add_database_options,
    build_options,
    build_wants,
    non_negative,
    positive,
)
from alphafence.errors import need


def register(sub):
    """Add the ``build`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "build",
        help="build fences from a geofence database",
        description="Build alpha-shape (or polygon, circle, exact) fences around restricted sites.",
    )
    add_database_options(p)
    p.add_argument(
        "-o", "--output", required=True, metavar="FENCES.geojson", help="GeoJSON output (lon, lat)"
    )
    p.add_argument(
        "--plan", metavar="FILE.plan", help="also write a QGroundControl plan (geoFence)"
    )
    p.add_argument(
        "--waypoints", metavar="FILE.waypoints", help="also write an ArduPilot fence waypoint file"
    )
    p.add_argument("--figure", metavar="MAP.png", help="also draw the fences on a map")
    p.add_argument(
        "--method", choices=METHODS, default="alpha", help="fence method (default alpha)"
    )
    p.add_argument(
        "--alpha-radius",
        type=positive("--alpha-radius", "metres"),
        metavar="M",
        help="force one alpha radius (metres) for every site",
    )
    p.add_argument(
        "--warn-distance",
        type=non_negative("--warn-distance", "metres"),
        default=30.0,
        metavar="M",
        help="warning layer this far beyond each keep-out fence (default 30; 0 = none)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(func=run)


def run(args) -> int:
    """Read the databases, build the fences, write them; exit status 0."""
    from alphafence.build.outputs import build_meta, render
    from alphafence.build.pipeline import build_fences
    from alphafence.formats.atomic import write_all
    from alphafence.formats.database import read_database
    from alphafence.formats.rules import load_rules

    need(*build_wants(args.databases, args.figure))
    rules = load_rules(args.rules)
    opts = build_options(args)
    with progress(not args.quiet) as prog:
        if prog is not None:
            t = prog.add_task("reading " + ", ".join(args.databases), total=None)
        db = read_database(args.databases, rules, args.bbox, bbox_name="--bbox")
        if prog is not None:
            prog.remove_task(t)
        result = build_fences(db.features, rules, opts, progress=callback(prog, "fencing sites"))
    meta = build_meta(db, rules, opts)
    outputs = render(result.fences, meta, args.output, args.plan, args.waypoints)
    write_all(outputs)
    written = list(outputs)
    if args.figure:
        from alphafence.plots.fences import fence_map

        fence_map(
            result.fences,
            result.sites,
            args.figure,
            title=f"AlphaFence: {opts.method} fences",
            note=meta.get("attribution"),
        )
        written.append(args.figure)
    if not args.quiet:
        summary(db, result, opts, written)
    return 0


def summary(db, result, opts, written):
    """Print the fences built per category and kind, and notes on repairs, skipped features
    and what does not fit a vehicle."""
    import numpy as np

    from alphafence.mavlink.items import MAX_POLYGON_VERTICES, fence_items
    from alphafence.mavlink.storage import PROFILES

    copter_items = PROFILES["copter"].items
    fences = result.fences
    table = Table(
        title=f"{len(result.sites)} sites from {len(db.features)} restricted features "
        f"({opts.method} fences, {sum(result.seconds.values()):.2f} s)"
    )
    for col in ("category", "kind", "sites", "fences", "vertices (median / max)", "area km²"):
        table.add_column(col, justify="right" if col not in ("category", "kind") else "left")
    groups = defaultdict(list)
    for f in fences:
        groups[(f.category, f.kind)].append(f)
    site_count = Counter((s.category, s.kind) for s in result.sites)
    for (cat, kind), fs in sorted(groups.items()):
        v = [f.vertices for f in fs]
        table.add_row(
            cat,
            kind,
            str(site_count.get((cat, kind), "")),
            str(len(fs)),
            f"{np.median(v):.0f} / {max(v)}",
            f"{sum(f.area_m2 for f in fs) / 1e6:.3f}",
        )
    out_console.print(table)
    notes = []
    if db.repaired:
        shown = ", ".join(db.repaired[:5]) + (" ..." if len(db.repaired) > 5 else "")
        notes.append(f"repaired {len(db.repaired)} invalid (self-intersecting) polygon(s): {shown}")
    for reason, n in db.skipped.items():
        notes.append(f"skipped {n} feature(s): {reason}")
    fixed = [f.site_id for f in fences if f.repaired]
    if fixed:
        notes.append(
            f"{len(fixed)} fence(s) re-united with their site after a containment check: {', '.join(fixed[:5])}"
        )
    items = fence_items(fences)
    big = [
        f.site_id
        for f in fences
        if f.kind != "warning" and f.circle is None and f.vertices > MAX_POLYGON_VERTICES
    ]
    if big:
        notes.append(f"{len(big)} polygon(s) exceed ArduPilot's 255 vertices: {', '.join(big[:3])}")
    if len(items) > copter_items:
        notes.append(
            f"{len(items)} fence items: more than a Copter holds ({copter_items}); "
            "compile an onboard subset for the operating area before uploading"
        )
    for n in notes:
        err_console.print(f"[yellow]note:[/] {n}")
    out_console.print("wrote " + ", ".join(written))
