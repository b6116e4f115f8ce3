"""alphafence route: a mission from A to B that keeps a clearance from every keep-out fence."""

from __future__ import annotations

from alphafence.cli.common import out_console
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.options import figure_wants, latlon, non_negative, positive
from alphafence.errors import InputError, RoutingError, need


def register(sub):
    """Add the ``route`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "route",
        help="plan a mission around the keep-out fences",
        description="Route from --from to --to on a Voronoi roadmap clear of every keep-out "
        "fence by --clearance (warning layers cost more than open air), built over the fences "
        "in a corridor around the two (widened while the route comes too close to a fence "
        "outside it), smooth it by line of sight, and write a QGroundControl mission: "
        "takeoff, waypoints, RTL. "
        "Exit code 1 when no route exists (one line says what blocks it), 2 on bad input.",
    )
    p.add_argument("fences", metavar="FENCES", help="fences from 'alphafence build' (GeoJSON)")
    p.add_argument(
        "--from",
        dest="start",
        type=latlon("--from"),
        required=True,
        metavar="LAT,LON",
        help="start",
    )
    p.add_argument(
        "--to", dest="goal", type=latlon("--to"), required=True, metavar="LAT,LON", help="goal"
    )
    p.add_argument(
        "--alt",
        type=positive("--alt", "metres"),
        default=30.0,
        metavar="M",
        help="altitude above home (default 30)",
    )
    p.add_argument(
        "--clearance",
        type=non_negative("--clearance"),
        default=20.0,
        metavar="M",
        help="least distance from any keep-out fence (default 20)",
    )
    p.add_argument(
        "--one-way",
        action="store_true",
        help="end with RTL at the goal (RTL flies straight home, across any fence); "
        "by default the mission flies the route back before RTL",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="MISSION.plan",
        help="the mission, by its suffix: .plan (QGroundControl plan) or .waypoints "
        "(QGC WPL 110 mission file)",
    )
    p.add_argument(
        "--beyond-fences",
        action="store_true",
        help="route to or from a point more than 50 km from every fence (an area these "
        "fences do not describe: nothing there is known to be clear); refused without it",
    )
    p.add_argument("--waypoints", metavar="FILE", help="also write a QGC WPL 110 mission file")
    p.add_argument("--figure", metavar="PNG", help="draw fences, roadmap and route")
    add_map_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Plan the route and write the mission; exit 0, or 1 (a
    :class:`~alphafence.errors.RoutingError`) when no route exists."""
    from alphafence.fencefiles import qgc_plan as plan
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencefiles.fence_read import read_fence_file as read_fences
    from alphafence.fencefiles.qgc_plan import mission_items
    from alphafence.fencefiles.qgc_wpl import mission_waypoints_text
    from alphafence.route import CorridorPlanner, NoRoute
    from alphafence.route.corridor import REACH_M
    from alphafence.zones.mistakes import output_format

    fmt = output_format(args.output, what="mission output")  # before the routing
    need(("scipy", "routing"), *figure_wants(args.figure))
    check_map_args(args)

    start, goal = args.start, args.goal
    records = read_fences(args.fences)
    _check_ends(args, records)
    if not any(r.kind == "keep_out" for r in records):
        out_console.print("[yellow]note:[/] no keep-out fences: the route is a straight line")
    planner = CorridorPlanner(records, start, goal, clearance=args.clearance)
    if planner.out_of_reach:
        out_console.print(
            f"[yellow]note:[/] {planner.out_of_reach} fences more than "
            f"{REACH_M / 1000:,.0f} km away are left out"
        )
    try:
        route, lonlat = planner.route(progress=_print_corridor)
    except NoRoute as exc:
        raise RoutingError(f"{args.fences}: no route: {exc}") from None
    items = mission_items(lonlat, args.alt, fly_back=not args.one_way)
    if fmt == "plan":
        out = {args.output: plan.dumps(plan.plan_document([], start, items))}
    else:
        out = {args.output: mission_waypoints_text(items, start)}
    if args.waypoints:
        out[args.waypoints] = mission_waypoints_text(items, start)
    if args.figure:  # drawn first: the slow part, before any file is written
        from alphafence.plots.route import route_figure

        route_figure(planner.roadmap, route, args.figure, planner.frame, records)
    write_all(out)
    if args.map:
        from alphafence.cli.maps import write_map_page
        from alphafence.plots.webmap import fence_layers
        from alphafence.plots.webmap_layers import records_near, route_layers

        near = records_near(records, planner.frame, route.xy, max(planner.half_width, 1000.0))
        layers = [*fence_layers(near), *route_layers(planner, route, lonlat)]
        title = f"Route {route.length_m:,.0f} m, {len(lonlat) - 1} legs"
        write_map_page(args, title, layers)
    if planner.added:
        out_console.print(
            f"[yellow]note:[/] {planner.added} waypoints added along long legs: ArduPilot flies "
            "a leg as a straight line in lon/lat, which bows away from the planned line"
        )
    if args.one_way:
        out_console.print(
            "[yellow]note:[/] --one-way: the final RTL flies straight home; "
            "check it with 'alphafence check-mission'"
        )
    straight = float(sum((planner.goal_xy - planner.start_xy) ** 2) ** 0.5)
    out_console.print(
        f"route {route.length_m:.0f} m ({route.length_m / max(straight, 1e-9):.3f}x straight "
        f"line), {len(route.xy) - 1} legs, min clearance {route.min_clearance_m:.1f} m "
        f"(asked {args.clearance:g} m)"
        + (f", {route.warning_m:.0f} m inside warning layers" if route.warning_m > 0 else "")
    )
    shown = [*out, *([args.figure] if args.figure else []), *([args.map] if args.map else [])]
    out_console.print("wrote " + ", ".join(str(p) for p in shown))
    return 0


def _check_ends(args, records):
    """Refuse an end typed LON,LAT (far from every fence, its swap among them), and an end
    more than 50 km from every fence unless ``--beyond-fences`` (a typing slip, or fences
    for another area: a route there crosses ground these fences do not describe)."""
    from alphafence.zones.mistakes import FAR_M, check_point

    geoms = [r.geometry for r in records]
    for name, lonlat in (("--from", args.start), ("--to", args.goal)):
        distance = check_point(name, lonlat, geoms, args.fences)
        if not geoms or distance <= FAR_M:
            continue
        where = f"{lonlat[1]:g},{lonlat[0]:g} (LAT,LON) is {distance / 1000:,.0f} km"
        if not args.beyond_fences:
            raise InputError(
                name,
                f"{where} from every fence of {args.fences}: the route would cross ground "
                "these fences do not describe; check the value, build fences for the whole "
                "way, or pass --beyond-fences",
            )
        out_console.print(
            f"[yellow]note:[/] {name} {where} from the nearest fence of {args.fences}",
            highlight=False,
        )


def _print_corridor(corridor):
    """One line as the planner starts on a corridor (a wider one says why)."""
    why = ""
    if corridor.number > 1:
        why = " (the last route came too close to fences outside)"
    out_console.print(
        f"corridor {corridor.number}: {len(corridor.fences)} of {corridor.total} keep-out "
        f"fences within {corridor.half_width_m / 1000:,.1f} km of the line{why}",
        highlight=False,
    )
