"""alphafence check-mission: which legs of a mission cross or graze keep-out fences."""

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
        "file) that cross a keep-out fence or come within --clearance of one. Exit code 1 "
        "when any leg crosses a keep-out fence, 2 on bad input, else 0.",
    )
    p.add_argument("mission", metavar="MISSION", help="QGroundControl .plan or QGC WPL file")
    p.add_argument("--fences", required=True, metavar="FENCES", help="fence GeoJSON")
    p.add_argument(
        "--clearance",
        type=non_negative("--clearance"),
        default=20.0,
        metavar="M",
        help="legs closer than M metres graze a fence (default 20)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    """Print the legs near keep-out fences; exit 1 when any leg crosses one, else 0."""
    from alphafence.formats.fence_read import read_fence_file as read_fences
    from alphafence.formats.mission import read_mission
    from alphafence.route.legs import check_legs

    records = read_fences(args.fences)
    waypoints = read_mission(args.mission)
    issues, legs, warning_legs = check_legs(waypoints, records, args.clearance)
    crossing = {i.leg for i in issues if i.crosses}
    grazing = {i.leg for i in issues if not i.crosses} - crossing
    if issues:
        t = Table(title=f"{args.mission}: legs near keep-out fences")
        for col in ("leg", "from", "to", "fence", "distance m", "verdict"):
            t.add_column(col, justify="right" if col in ("leg", "distance m") else "left")
        for i in issues:
            t.add_row(
                str(i.leg),
                i.start,
                i.end,
                i.fence,
                f"{i.distance_m:.1f}",
                "[red]CROSSES[/]" if i.crosses else f"[yellow]grazes[/] (< {args.clearance:g} m)",
            )
        out_console.print(t)
    if warning_legs:
        err_console.print(
            f"[yellow]note:[/] leg(s) {', '.join(map(str, sorted(warning_legs)))} "
            "pass through warning layers"
        )
    out_console.print(
        f"{len(legs)} legs: {len(crossing)} cross a keep-out fence, {len(grazing)} graze one "
        f"(within {args.clearance:g} m), {len(legs) - len(crossing) - len(grazing)} clear"
    )
    return 1 if crossing else 0
