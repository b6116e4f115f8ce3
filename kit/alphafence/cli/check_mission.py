"""alphafence check-mission: which legs of a mission, at their altitudes, cross or graze
keep-out fences, or leave keep-in fences (each fence's altitude band in its own reference)."""

from __future__ import annotations

from rich.table import Table

from alphafence.cli.common import err_console, out_console
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.options import non_negative


def register(sub):
    """Add the ``check-mission`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "check-mission",
        help="check a mission's legs against fences",
        description="List the legs of a mission (QGroundControl .plan or QGC WPL waypoint "
        "file) that cross a keep-out fence or come within --clearance of one, or leave a "
        "keep-in fence or come within --clearance of its edge. Every NAV command with a "
        "position is a leg's end; DO_JUMP is followed (each leg checked once). Each leg flies "
        "its items' altitudes (frame relative to home, AMSL with the plan's home altitude, "
        "or above the terrain; linear along a leg; takeoff climbs where it is, landing "
        "descends at its position, RTL climbs to at least --rtl-alt) and meets each fence's "
        "altitude band in the band's own reference; what cannot be compared (terrain without "
        "terrain data, AMSL limits without home's altitude AMSL) counts against the leg, with "
        "a note. Exit code 1 when any leg crosses a keep-out fence or leaves a keep-in fence, "
        "2 on bad input, else 0.",
    )
    p.add_argument("mission", metavar="MISSION", help="QGroundControl .plan or QGC WPL file")
    p.add_argument(
        "--fences",
        required=True,
        metavar="FENCES",
        help="fence file: the kit's GeoJSON (or sequence, GeoParquet), a QGroundControl .plan "
        "geoFence, a fence .waypoints file, ArduPilot's legacy fence file, KML/KMZ or OpenAir",
    )
    p.add_argument(
        "--clearance",
        type=non_negative("--clearance"),
        default=20.0,
        metavar="M",
        help="legs closer than M metres to a fence (or a keep-in fence's edge) graze it, "
        "horizontally or vertically (default 20)",
    )
    p.add_argument(
        "--rtl-alt",
        type=non_negative("--rtl-alt", "metres"),
        default=15.0,
        metavar="M",
        help="the altitude above home RTL climbs to at least: the vehicle's RTL_ALT "
        "(default 15, ArduCopter's; ArduPlane's ALT_HOLD_RTL is 100)",
    )
    add_map_options(p)
    p.set_defaults(func=run)


def _verdict(issue, clearance) -> str:
    if issue.keep_in:
        return (
            "[red]LEAVES[/]" if issue.crosses else f"[yellow]near its edge[/] (< {clearance:g} m)"
        )
    return "[red]CROSSES[/]" if issue.crosses else f"[yellow]grazes[/] (< {clearance:g} m)"


def _altitudes(leg) -> str:
    """A leg's altitudes for the table: ``"30-150"`` at its start and end (``^45``: the
    highest between), ``terrain`` or ``amsl`` after them where not above home; ``?`` when not
    known."""
    prof = leg.profile
    if not prof or leg.frame is None:
        return "?"
    start, end, top = prof[0][1], prof[-1][1], max(z for _, z in prof)
    text = f"{start:g}" if start == end else f"{start:g}-{end:g}"
    text += f" ^{top:g}" if top > max(start, end) else ""
    return text + {"home": "", "amsl": " amsl", "terrain": " terrain"}[leg.frame]


def run(args) -> int:
    """Print the legs near keep-out fences and keep-in fences' edges; exit 1 when any leg
    crosses a keep-out fence or leaves a keep-in fence, else 0."""
    from alphafence.fencefiles.fence_read import read_fence_file as read_fences
    from alphafence.flights.mission import load_mission
    from alphafence.review.mission_check import check_mission

    check_map_args(args)
    records = read_fences(args.fences)
    mission = load_mission(args.mission, rtl_alt_m=args.rtl_alt)
    result = check_mission(mission, records, args.clearance)
    issues, legs, warning_legs = result.issues, result.legs, result.warning_legs
    ends = {n: b for n, _, b in legs}
    crossing = {i.leg for i in issues if i.crosses and not i.keep_in}
    leaving = {i.leg for i in issues if i.crosses and i.keep_in} - crossing
    grazing = {i.leg for i in issues if not i.crosses} - crossing - leaving
    if issues:
        t = Table(title=f"{args.mission}: legs near keep-out fences or keep-in fences' edges")
        for col in ("leg", "from", "to", "alt m", "fence", "distance m", "verdict"):
            t.add_column(col, justify="right" if col in ("leg", "distance m") else "left")
        for i in issues:
            t.add_row(
                str(i.leg),
                i.start,
                i.end,
                _altitudes(ends[i.leg]),
                i.fence + (" (keep-in)" if i.keep_in else ""),
                f"{i.distance_m:.1f}",
                _verdict(i, args.clearance),
            )
        out_console.print(t)
    if warning_legs:
        err_console.print(
            f"[yellow]note:[/] leg(s) {', '.join(map(str, sorted(warning_legs)))} "
            "pass through warning layers"
        )
    for note in result.notes:
        err_console.print(f"[yellow]note:[/] {note}")
    clear = len(legs) - len(crossing) - len(leaving) - len(grazing)
    out_console.print(
        f"{len(legs)} legs: {len(crossing)} cross a keep-out fence, {len(grazing)} graze one "
        f"(within {args.clearance:g} m), {len(leaving)} leave a keep-in fence, {clear} clear"
    )
    if args.map:
        from alphafence.cli.maps import write_map_page
        from alphafence.plots.webmap import fence_layers
        from alphafence.plots.webmap_layers import mission_layers

        layers = [*fence_layers(records), *mission_layers(result, args.clearance)]
        title = f"{args.mission}: {len(legs)} legs"
        out_console.print(f"wrote {write_map_page(args, title, layers)}")
    return 1 if crossing or leaving else 0
