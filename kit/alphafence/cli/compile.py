"""alphafence compile: fences -> ArduPilot's fence storage for an operating area."""

from __future__ import annotations

import shapely
from rich.table import Table

from alphafence.cli.common import err_console, out_console
from alphafence.errors import InputError
from alphafence.formats import qgc_plan as plan
from alphafence.formats import qgc_wpl as waypoints
from alphafence.formats.atomic import write_all
from alphafence.formats.features import parse_bbox
from alphafence.formats.fence_geojson import read_fences
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences, operating_area_from_plan


def register(sub):
    p = sub.add_parser(
        "compile",
        help="compile fences into a vehicle's fence storage",
        description="Pick the fences near an operating area and fit them, conservatively "
        "simplified, into ArduPilot's fence storage.",
    )
    p.add_argument("fences", metavar="FENCES.geojson", help="fences from 'alphafence build'")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--area", metavar="MISSION.plan", help="operating area: the mission's positions"
    )
    where.add_argument(
        "--bbox", metavar="MINLON,MINLAT,MAXLON,MAXLAT", help="operating area: a box"
    )
    add_compile_options(p)
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="ONBOARD.plan",
        help="QGroundControl plan (geoFence)",
    )
    p.add_argument(
        "--waypoints", metavar="FILE", help="also write an ArduPilot fence waypoint file"
    )
    p.add_argument(
        "--figure", metavar="PNG", help="draw the onboard fences over the full-resolution ones"
    )
    p.set_defaults(func=run)


def add_compile_options(p):
    size = p.add_mutually_exclusive_group()
    size.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        default="copter",
        help="vehicle fence storage (default copter: 70 items, 560 bytes)",
    )
    p.add_argument("--items", type=int, metavar="N", help="at most N items (within the profile)")
    p.add_argument(
        "--distance",
        type=float,
        default=2000.0,
        metavar="M",
        help="fences within M metres of the area (default 2000)",
    )
    p.add_argument(
        "--keep-in", type=float, metavar="M", help="add an inclusion fence M metres around the area"
    )
    p.add_argument("--return-point", metavar="LAT,LON", help="the fence return point")


def parse_latlon(text):
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError("--return-point", f"expected LAT,LON, got {text!r}") from None
    return lon, lat


def compile_from_args(args, records):
    if getattr(args, "area", None):
        area, _ = operating_area_from_plan(args.area)
    else:
        b = parse_bbox(args.bbox)
        area = shapely.box(*b)
    if args.items is not None and args.items < 1:
        raise InputError("--items", "must be at least 1")
    rp = parse_latlon(args.return_point) if args.return_point else None
    return compile_fences(
        records, area, PROFILES[args.profile], args.distance, args.keep_in, rp, args.items
    )


def run(args) -> int:
    records = read_fences(args.fences)
    result = compile_from_args(args, records)
    out = {
        args.output: plan.dumps(plan.plan_document(result.items, breach_return=result.return_point))
    }
    if args.waypoints:
        out[args.waypoints] = waypoints.waypoints_text(result.items)
    write_all(out)
    report(result)
    if args.figure:
        from alphafence.plots.fences import onboard_figure

        onboard_figure(records, result, args.figure)
    out_console.print(
        "wrote " + ", ".join(str(p) for p in [*out, *([args.figure] if args.figure else [])])
    )
    return 0


def report(result):
    t = Table(
        title=f"{len(result.items)} items, {result.bytes_used} of {result.profile.bytes} bytes "
        f"({result.profile.name}); area added {result.loss_m2 / 1e4:.2f} ha"
    )
    for col in ("fence(s)", "kind", "stored as", "items", "bytes", "area lost m²"):
        t.add_column(col, justify="left" if col in ("fence(s)", "kind", "stored as") else "right")
    for p in result.pieces:
        o = p.chosen
        full = len(p.local.exterior.coords) - 1
        label = ", ".join(p.sources[:3]) + (
            f" (+{len(p.sources) - 3})" if len(p.sources) > 3 else ""
        )
        how = (
            o.label
            + (" (merged)" if p.merged else "")
            + (f" of {full}" if o.kind == "polygon" and o.items < full else "")
        )
        t.add_row(
            label,
            "keep-in" if p.inclusion else "keep-out",
            how,
            str(o.items),
            str(o.bytes),
            f"{o.loss:.0f}",
        )
    out_console.print(t)
    if result.dropped:
        err_console.print(
            f"[yellow]note:[/] {len(result.dropped)} fence(s) farther than the selection distance were left out"
        )
    for m in result.merges:
        err_console.print(f"[yellow]note:[/] merged {', '.join(m)} to fit the storage")
