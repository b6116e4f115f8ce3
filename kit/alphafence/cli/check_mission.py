"""alphafence check-mission: which legs of a mission cross or graze keep-out fences, or leave
keep-in fences."""

from __future__ import annotations

from rich.table import Table

from alphafence.cli.common import err_console, out_console
from alphafence.cli.options import non_negative


def register(sub):
    """Add the ``check-mission`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "check-mission",
        help="check a mission's legs against fences",
        description="List the legs of a mission (QGroundControl .plan or QGC WPL waypoint "
        "file) that cross a keep-out fence or come within --clearance of one, or leave a "
        "keep-in fence or come within --clearance of its edge. Every NAV command with a "
        "position is a leg's end; DO_JUMP is followed (each leg checked once). Exit code 1 "
        "when any leg crosses a keep-out fence or leaves a keep-in fence, 2 on bad input, "
        "else 0.",
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
        help="legs closer than M metres to a fence (or a keep-in fence's edge) graze it "
        "(default 20)",
    )
    p.set_defaults(func=run)


def _verdict(issue, clearance) -> str:
    if issue.keep_in:
        return (
            "[red]LEAVES[/]" if issue.crosses else f"[yellow]near its edge[/] (< {clearance:g} m)"
        )
    return "[red]CROSSES[/]" if issue.crosses else f"[yellow]grazes[/] (< {clearance:g} m)"


def run(args) -> int:
    """Print the legs near keep-out fences and keep-in fences' edges; exit 1 when any leg
    crosses a keep-out fence or leaves a keep-in fence, else 0."""
    from alphafence.formats.fence_read import read_fence_file as read_fences
    from alphafence.formats.mission import read_mission
    from alphafence.route.legs import check_legs

    records = read_fences(args.fences)
    waypoints = read_mission(args.mission)
    issues, legs, warning_legs = check_legs(waypoints, records, args.clearance)
    crossing = {i.leg for i in issues if i.crosses and not i.keep_in}
    leaving = {i.leg for i in issues if i.crosses and i.keep_in} - crossing
    grazing = {i.leg for i in issues if not i.crosses} - crossing - leaving
    if issues:
        t = Table(title=f"{args.mission}: legs near keep-out fences or keep-in fences' edges")
        for col in ("leg", "from", "to", "fence", "distance m", "verdict"):
            t.add_column(col, justify="right" if col in ("leg", "distance m") else "left")
        for i in issues:
            t.add_row(
                str(i.leg),
                i.start,
                i.end,
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
    clear = len(legs) - len(crossing) - len(leaving) - len(grazing)
    out_console.print(
        f"{len(legs)} legs: {len(crossing)} cross a keep-out fence, {len(grazing)} graze one "
        f"(within {args.clearance:g} m), {len(leaving)} leave a keep-in fence, {clear} clear"
    )
    return 1 if crossing or leaving else 0
