"""alphafence compile: fences -> a vehicle's fence storage (ArduPilot's or PX4's) for a mission's
flight path (or a box)."""

from __future__ import annotations

from alphafence.cli.common import out_console, union_hint
from alphafence.cli.maps import add_map_options, check_map_args, onboard_map
from alphafence.cli.options import add_compile_options, bbox, compile_from_args, figure_wants
from alphafence.cli.source_options import add_source_options, with_source
from alphafence.cli.tables import compile_report
from alphafence.errors import need


def register(sub):
    """Add the ``compile`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "compile",
        help="compile fences into a vehicle's fence storage",
        description="Pick the fences within --distance of a mission's flight path (or of a "
        "box) and fit them, conservatively simplified, into the fence storage of ArduPilot "
        "(or PX4, --autopilot px4), "
        "spending the bytes where the path runs close to a fence.",
    )
    p.add_argument("fences", metavar="FENCES.geojson", help="fences from 'alphafence build'")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "--area",
        metavar="MISSION.plan",
        help="fly this mission: fences near its legs (the way back included)",
    )
    where.add_argument(
        "--bbox", type=bbox, metavar="MINLON,MINLAT,MAXLON,MAXLAT", help="operating area: a box"
    )
    add_compile_options(p)
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="ONBOARD.plan",
        help="the onboard fence, by its suffix: .plan (QGroundControl plan, geoFence) or "
        ".waypoints (ArduPilot fence waypoint file)",
    )
    p.add_argument(
        "--waypoints", metavar="FILE", help="also write an ArduPilot fence waypoint file"
    )
    p.add_argument(
        "--sign-key",
        metavar="KEY.pem",
        help="sign what is written with this Ed25519 private key (from 'alphafence bundle "
        "keygen'): ONBOARD.plan.sig.json beside it, as 'bundle sign' does, for 'upload "
        "--trusted-key KEY.pub.pem'",
    )
    p.add_argument(
        "--figure",
        metavar="PNG",
        help="draw the onboard fences over the full-resolution ones, the path and the corridor",
    )
    add_map_options(p)
    add_source_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Compile the fences for the flight path or box, write the onboard plan or waypoint file
    (``-o``'s suffix says which; ``--waypoints`` also); exit 0, or 2 on bad input (an unknown
    output suffix, a box typed lat,lon, no fence near the area)."""
    from alphafence.fencefiles import qgc_plan as plan
    from alphafence.fencefiles import qgc_wpl as waypoints
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencefiles.fence_read import read_fence_file as read_fences
    from alphafence.mavlink import ids
    from alphafence.zones.mistakes import output_format

    fmt = output_format(args.output, what="onboard fence output")  # before any work
    need(*figure_wants(args.figure))
    if args.sign_key:
        from alphafence.fencing.bundle import check_private_key

        check_private_key(args.sign_key)
    check_map_args(args)
    records = with_source(args, read_fences(args.fences))
    result = compile_from_args(args, records)
    if fmt == "plan":
        sites = result.fence_sites()  # which site each polygon and circle stands for
        firmware = ids.MAV_AUTOPILOT_PX4 if result.profile.autopilot == "px4" else None
        doc = plan.plan_document(
            result.items, breach_return=result.return_point, sites=sites,
            **({"firmware": firmware} if firmware else {}),
        )  # fmt: skip
        out = {args.output: plan.dumps(doc)}
    else:
        out = {args.output: waypoints.waypoints_text(result.items)}
    if args.waypoints:
        out[args.waypoints] = waypoints.waypoints_text(result.items)
    write_all(out)
    if args.sign_key:
        from alphafence.fencing.bundle import sign

        out.update({sign(path, args.sign_key): None for path in list(out)})
    compile_report(result)
    union_hint(result.items)
    if args.figure:
        from alphafence.plots.fences import onboard_figure

        onboard_figure(records, result, args.figure)
    if args.map:
        onboard_map(args, records, result, f"{args.fences}: {len(result.items)} onboard items")
    shown = [*out, *([args.figure] if args.figure else []), *([args.map] if args.map else [])]
    out_console.print("wrote " + ", ".join(str(p) for p in shown))
    return 0
