"""alphafence download: read the vehicle's fence into a .plan (and a waypoint file)."""

from __future__ import annotations

import asyncio

from alphafence.cli.common import (
    add_link_option,
    add_signing_option,
    out_console,
    signing_key,
    unsigned_hint,
)
from alphafence.cli.options import add_connect_option


def register(sub):
    """Add the ``download`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "download",
        help="read the fence a vehicle holds",
        description="Download the vehicle's fence items into a QGroundControl plan.",
    )
    add_connect_option(p)
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT.plan",
        help="the fence, by its suffix: .plan (QGroundControl plan, geoFence) or .waypoints "
        "(ArduPilot fence waypoint file)",
    )
    p.add_argument(
        "--waypoints", metavar="FILE", help="also write an ArduPilot fence waypoint file"
    )
    p.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    add_signing_option(p)
    add_link_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Download the vehicle's fence and write it (``-o``'s suffix says how); exit 0, 2 for an
    unknown output suffix, or 3 when the vehicle or the link fails (a
    :class:`~alphafence.errors.VehicleError`)."""
    from alphafence.zones.mistakes import output_format

    args.format = output_format(args.output, what="fence output")  # before connecting
    args.key = signing_key(args)
    return asyncio.run(_download(args))


async def _download(args) -> int:
    from alphafence.fencefiles import qgc_plan as plan
    from alphafence.fencefiles import qgc_wpl as waypoints
    from alphafence.fencefiles.atomic import write_all
    from alphafence.vehicle.fence_transfer import download_fence
    from alphafence.vehicle.link import open_vehicle

    with unsigned_hint(args.key):
        async with open_vehicle(args.connect, args.timeout, args.key, args.link) as vehicle:
            items = await download_fence(vehicle)
    if args.format == "plan":
        out = {args.output: plan.dumps(plan.plan_document(items))}
    else:
        out = {args.output: waypoints.waypoints_text(items)}
    if args.waypoints:
        out[args.waypoints] = waypoints.waypoints_text(items)
    write_all(out)
    out_console.print(f"downloaded {len(items)} fence items -> {', '.join(out)}")
    return 0
