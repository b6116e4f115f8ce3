"""alphafence upload: compile (if needed), upload, verify by reading back, set fence parameters."""

from __future__ import annotations

import asyncio

from alphafence.cli.common import (
    add_signing_option,
    add_trust_options,
    check_trust,
    out_console,
    signing_key,
    unsigned_hint,
)
from alphafence.cli.options import add_compile_options, bbox, compile_from_args
from alphafence.cli.tables import compile_report
from alphafence.errors import InputError
from alphafence.formats.fence_geojson import read_fences
from alphafence.formats.qgc_plan import read_plan_fence
from alphafence.formats.qgc_wpl import read_waypoints_fence
from alphafence.vehicle.params import PROFILES as PARAM_PROFILES


def register(sub):
    """Add the ``upload`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "upload",
        help="upload fences to a vehicle and verify them",
        description="Upload fences (a fence GeoJSON, compiled here, or an onboard .plan / "
        ".waypoints) with the MAVLink mission protocol, read them back and compare.",
    )
    p.add_argument(
        "fences",
        metavar="FENCES",
        help="fences .geojson (compiled first), or onboard .plan / .waypoints",
    )
    p.add_argument(
        "--connect",
        required=False,
        metavar="URL",
        help="MAVSDK connection URL, e.g. udpin://127.0.0.1:14550 or tcpout://navio.local:5760",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--area", metavar="MISSION.plan", help="operating area (for a .geojson)")
    where.add_argument(
        "--bbox",
        type=bbox,
        metavar="MINLON,MINLAT,MAXLON,MAXLAT",
        help="operating area (for a .geojson)",
    )
    add_compile_options(p)
    p.add_argument(
        "--params",
        choices=sorted(PARAM_PROFILES),
        help="also set and verify these fence parameters",
    )
    p.add_argument("--dry-run", action="store_true", help="compile and check, but do not connect")
    add_trust_options(p)
    add_signing_option(p)
    p.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    p.set_defaults(func=run)


def load_items(args):
    """The fence items to upload and, for a fence GeoJSON, the compilation that made them.

    Returns
    -------
    tuple
        ``(items, CompileResult or None)``.
    """
    name = args.fences.lower()
    if name.endswith(".plan"):
        return read_plan_fence(args.fences), None
    if name.endswith((".waypoints", ".txt")):
        return read_waypoints_fence(args.fences), None
    if not (args.area or args.bbox):
        raise InputError(
            args.fences, "a fence GeoJSON needs an operating area: --area MISSION.plan or --bbox"
        )
    result = compile_from_args(args, read_fences(args.fences))
    return result.items, result


def run(args) -> int:
    """Check the fences' signature, compile if needed, upload, read back, set parameters.

    Exit status 0, or 3 when the vehicle or the link fails (a
    :class:`~alphafence.errors.VehicleError`, mapped by :func:`alphafence.cli.main`).
    """
    check_trust(args, args.fences)
    items, compiled = load_items(args)
    if compiled is not None:
        compile_report(compiled)
    if args.dry_run:
        out_console.print(f"dry run: {len(items)} fence items ready; nothing sent")
        return 0
    if not args.connect:
        raise InputError("--connect", "needed unless --dry-run")
    args.key = signing_key(args)
    return asyncio.run(_upload(args, items))


async def _upload(args, items) -> int:
    from alphafence.vehicle.fence_transfer import upload_fence
    from alphafence.vehicle.link import open_vehicle
    from alphafence.vehicle.params import apply_params

    with unsigned_hint(args.key):
        async with open_vehicle(args.connect, args.timeout, args.key) as vehicle:
            rep = await upload_fence(vehicle, items)
            out_console.print(
                f"uploaded {rep.items} fence items and read them back identical ({rep.seconds:.2f} s)"
            )
            if args.params:
                got = await apply_params(vehicle, PARAM_PROFILES[args.params])
                out_console.print(
                    "parameters set and read back: "
                    + ", ".join(f"{k}={v:g}" for k, v in got.values.items())
                )
    return 0
