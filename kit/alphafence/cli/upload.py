"""alphafence upload: compile (if needed), upload, verify by reading back, set fence parameters.

An onboard ``.plan`` (its geoFence, either version, with its breach return point) or
``.waypoints`` file is checked as ArduPilot would check it and against the ``--profile``'s
storage (items and bytes, and ``--items``) before anything is sent, as a compiled fence GeoJSON
is; a dry run prints the items it would send (``--figure``: draws them).

With a file-backed storage profile (``--profile navio2``, ``sd-fence``) the vehicle's
``BRD_SD_FENCE`` is read first: too small, and the upload stops before anything is sent, or
with ``--reboot`` (disarmed only) it is set and the vehicle rebooted before the upload.
"""

from __future__ import annotations

import asyncio

from alphafence.cli.common import (
    add_link_option,
    add_signing_option,
    add_trust_options,
    check_trust,
    err_console,
    out_console,
    signing_key,
    unsigned_hint,
)
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.options import (
    add_compile_options,
    add_connect_option,
    bbox,
    compile_from_args,
    figure_wants,
    storage_profile,
)
from alphafence.cli.source_options import add_source_options, with_source
from alphafence.cli.tables import Presets, compile_report, gaps_report, items_report
from alphafence.errors import InputError, VehicleError, need
from alphafence.mavlink.autopilots import NAMES
from alphafence.mavlink.inclusions import UNION_WORDS, inclusion_count
from alphafence.vehicle.params import PROFILES as PARAM_PROFILES
from alphafence.vehicle.params import VEHICLE

# MAVSDK's results for a fence the vehicle has no room for (too many items; too many bytes)
NO_ROOM = ("TOO_MANY_MISSION_ITEMS", "PROTOCOL_ERROR")
NOT_YET_REBOOTED = (
    "BRD_SD_FENCE takes effect at boot: if it was set since the vehicle last booted, reboot it"
)


def register(sub):
    """Add the ``upload`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "upload",
        help="upload fences to a vehicle and verify them",
        description="Upload fences (a fence file compiled here, or an onboard .plan / "
        ".waypoints / ArduPilot legacy fence file) with the MAVLink mission protocol, read them "
        "back and compare.",
    )
    p.add_argument(
        "fences",
        metavar="FENCES",
        help="fences to compile (.geojson, KML, OpenAir...), or onboard .plan / .waypoints / "
        "ArduPilot legacy fence file (lat lon lines, often .txt)",
    )
    add_connect_option(p, required=False)
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
        action=Presets,
        choices=[*PARAM_PROFILES, "list"],
        metavar="PRESET",
        help="also set and verify the fence parameters of this preset, for the vehicle's type "
        f"({', '.join(PARAM_PROFILES)}); 'list' prints each preset's parameters",
    )
    p.add_argument(
        "--reboot",
        action="store_true",
        help="with --profile navio2 (or sd-fence): when the vehicle's BRD_SD_FENCE is too small, "
        "set it and reboot the vehicle (only while disarmed), then upload",
    )
    p.add_argument("--dry-run", action="store_true", help="compile and check, but do not connect")
    p.add_argument(
        "--figure",
        metavar="PNG",
        help="draw the fence items it sends: polygons and circles (inclusion green, exclusion "
        "red) and the return point",
    )
    add_map_options(p)
    add_trust_options(p)
    add_signing_option(p)
    add_link_option(p)
    add_source_options(p)
    p.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    p.set_defaults(func=run)


def onboard_file(args) -> str | None:
    """What kind of onboard file ``args.fences`` is (``"plan"``, ``"waypoints"``,
    ``"legacy"``), or None for fences to compile."""
    from alphafence.fencefiles.ardupilot_fence import onboard_kind

    name = args.fences.lower()
    if name.endswith(".plan"):
        return "plan"
    kind = "waypoints" if name.endswith(".waypoints") else onboard_kind(args.fences)
    return kind if kind in ("waypoints", "legacy") else None


def read_records(args):
    """The fences of ``args.fences`` to compile (with ``--source``'s), read and checked
    before the vehicle is asked anything; None for an onboard file."""
    from alphafence.fencefiles.fence_read import read_fence_file as read_fences

    if onboard_file(args) is not None:
        return None
    if not (args.area or args.bbox):
        raise InputError(
            args.fences,
            "fences to compile (fence GeoJSON, KML, OpenAir...) need an operating area: "
            "--area MISSION.plan or --bbox",
        )
    return with_source(args, read_fences(args.fences))


def load_items(args, home=None, position=None, records=None):
    """The fence items to upload and, for a fence GeoJSON, the compilation that made them.

    An onboard ``.plan`` gives its geoFence's items with its breach return point first; a
    ``.waypoints`` file (or a QGC WPL file of another suffix, ``.txt``) its items as they are;
    ArduPilot's legacy fence file (``lat lon`` lines, told by its content) its return point
    and its inclusion polygon. Any other file (its ``records``, when read already) is compiled
    for ``--area`` or ``--bbox``, leaving ``home`` and ``position`` (the vehicle's,
    ``(lon, lat)``) clear.

    Returns
    -------
    tuple
        ``(items, CompileResult or None)``.
    """
    from alphafence.fencefiles.ardupilot_fence import read_legacy_items
    from alphafence.fencefiles.qgc_plan import read_plan_geofence
    from alphafence.fencefiles.qgc_wpl import read_waypoints_fence

    kind = onboard_file(args)
    if kind == "plan":
        return read_plan_geofence(args.fences).upload_items, None
    if kind == "waypoints":
        return read_waypoints_fence(args.fences), None
    if kind == "legacy":
        return read_legacy_items(args.fences), None
    records = read_records(args) if records is None else records
    result = compile_from_args(args, records, home, position)
    return result.items, result


def plan_sites(path):
    """The sites each polygon and circle of a compiled ``.plan`` stands for (None for other
    files)."""
    from alphafence.fencefiles.qgc_plan import read_plan_geofence

    return read_plan_geofence(path).sites if path.lower().endswith(".plan") else None


def prepare(args, home=None, position=None, records=None):
    """Compile the fences for ``args.autopilot`` (leaving the vehicle's ``home`` and
    ``position`` clear; or check an onboard file's items against its storage and rules), with
    the reports, figure and map asked for.

    Returns
    -------
    tuple
        ``(items, Profile)``.
    """
    from alphafence.onboard.decode import decode_fence
    from alphafence.onboard.rules import check_for_autopilot, check_items

    profile = storage_profile(args)
    if args.reboot and not profile.file_backed:
        raise InputError(
            "--reboot",
            f"sets BRD_SD_FENCE for --profile navio2 or sd-fence; the {profile.name} profile's "
            "storage needs no reboot",
        )
    items, compiled = load_items(args, home, position, records)
    if compiled is not None:
        compile_report(compiled)
        gaps_report(compiled, getattr(args, "rule", None))
        fences = decode_fence(items, source=args.fences) if args.figure or args.map else None
    else:
        fences = check_items(args.fences, items, profile, args.items)
        check_for_autopilot(items, profile.autopilot, args.fences)
        if args.dry_run:
            items_report(items, fences, profile, plan_sites(args.fences))
    if args.figure or args.map:
        _pictures(args, items, fences, profile)
    if getattr(args, "area", None):
        _mission_outside(args.area, items)
    return items, profile


def _pictures(args, items, fences, profile) -> None:
    from alphafence.mavlink.items import RETURN_POINT

    ret = next(((i.lon, i.lat) for i in items if i.command == RETURN_POINT), None)
    title = f"{args.fences}: {len(items)} fence items ({profile.name})"
    if args.figure:
        from alphafence.plots.items import fence_items_figure

        fence_items_figure(fences, ret, args.figure, title)
    if args.map:
        from alphafence.cli.maps import write_map_page
        from alphafence.plots.webmap import onboard_layers

        out_console.print(f"wrote {write_map_page(args, title, onboard_layers(fences, ret))}")


def run(args) -> int:
    """Check the fences' signature, compile if needed (or check a plan's or waypoint file's
    items against the storage), upload, read back, set parameters.

    Fences to compile are compiled once the vehicle has said its autopilot, home and position.

    Exit status 0, or 3 when the vehicle or the link fails (a
    :class:`~alphafence.errors.VehicleError`, mapped by :func:`alphafence.cli.main`).
    """
    need(*figure_wants(args.figure))
    check_map_args(args)
    check_trust(args, args.fences)
    known = args.dry_run or args.autopilot or args.profile
    if known and args.params:  # a preset of the other autopilot: before any work
        autopilot = storage_profile(args).autopilot
        if (VEHICLE[args.params] == "px4") != (autopilot == "px4"):
            preset_for = "PX4" if VEHICLE[args.params] == "px4" else "ArduPilot"
            raise InputError(
                "--params",
                f"{args.params} is for {preset_for}; the fence is compiled for "
                f"{NAMES[autopilot]} (--autopilot, --profile)",
            )
    early = args.dry_run or (known and onboard_file(args) is not None)
    prepared = prepare(args) if early else None
    args.records = None if early else read_records(args)  # bad input: before any connection
    if args.dry_run:
        items = prepared[0]
        union = inclusion_count(items) > 1
        out_console.print(
            f"dry run: {len(items)} fence items ready"
            + (
                f" (the upload also sets {UNION_WORDS}, on ArduPilot 4.5 and later; for older "
                "firmware it compiles them as one inclusion and its gaps)"
                if union
                else ""
            )
            + "; nothing sent"
        )
        return 0
    if not args.connect:
        raise InputError("--connect", "needed unless --dry-run")
    args.key = signing_key(args)
    return asyncio.run(_upload(args, prepared))


async def _upload(args, prepared) -> int:
    from alphafence.vehicle.fence_transfer import FenceTransferError, upload_fence
    from alphafence.vehicle.link import open_vehicle
    from alphafence.vehicle.params import apply_params, check_preset, inclusion_rule
    from alphafence.vehicle.px4 import check_home, confirm_kept, monotonic
    from alphafence.vehicle.whereabouts import whereabouts

    with unsigned_hint(args.key):
        async with open_vehicle(args.connect, args.timeout, args.key, args.link) as vehicle:
            if prepared is None:  # compiled for the vehicle: its autopilot, home and position
                if not (args.autopilot or args.profile):
                    args.autopilot = vehicle.autopilot
                    out_console.print(f"the vehicle runs {NAMES[vehicle.autopilot]}")
                home, position = (None, None)
                if args.records is not None:  # fences to compile, round where it stands
                    home, position, said, warn = await whereabouts(
                        vehicle, args.home, args.home_clearance
                    )
                    (err_console if warn else out_console).print(
                        ("[yellow]warning:[/] " if warn else "") + said, soft_wrap=True
                    )
                if args.records is not None:  # several keep-in areas: as the firmware reads them
                    args.rule = await inclusion_rule(vehicle)
                    args.inclusions = args.rule[0]
                prepared = await asyncio.to_thread(prepare, args, home, position, args.records)
            items, profile = prepared
            if profile.autopilot != vehicle.autopilot:
                raise VehicleError(
                    f"the fence is compiled for {NAMES[profile.autopilot]}, and the vehicle runs "
                    f"{NAMES[vehicle.autopilot]} (its HEARTBEAT): compile it with --autopilot "
                    f"{vehicle.autopilot}; nothing was sent"
                )
            px4 = vehicle.autopilot == "px4"
            if args.params:
                await check_preset(vehicle, args.params)
            inclusions = inclusion_count(items)
            options = None
            if inclusions > 1 and not px4:
                rule, options, why = getattr(args, "rule", None) or await inclusion_rule(vehicle)
                if rule != "union":
                    raise VehicleError(
                        f"the fence has {inclusions} inclusion areas and {why}: compile it from "
                        "its fences (several keep-in areas are then one inclusion and an "
                        "exclusion per gap), or keep one keep-in area; nothing was sent"
                    )
            if px4:
                await check_home(vehicle, items, args.timeout)
            if profile.file_backed:
                await _storage(args, vehicle, items, profile)
            t0 = monotonic()
            try:
                rep = await upload_fence(vehicle, items, capacity=profile.items)
            except FenceTransferError as exc:
                if profile.file_backed and exc.result in NO_ROOM:
                    raise VehicleError(f"{exc} | {NOT_YET_REBOOTED}") from None
                raise
            out_console.print(
                f"uploaded {rep.items} fence items and read them back identical ({rep.seconds:.2f} s)"
            )
            if px4:
                await confirm_kept(vehicle, items, t0)
                out_console.print("PX4 keeps every area: home breaches none")
            if options is not None:
                await _union(vehicle, options, inclusions)
            if args.params:
                got = await apply_params(vehicle, PARAM_PROFILES[args.params])
                out_console.print(
                    "parameters set and read back: "
                    + ", ".join(f"{k}={v:g}" for k, v in got.values.items())
                )
    return 0


def _mission_outside(plan, items) -> None:
    """Warn when home or a position of the mission breaches the fence as the vehicle will
    read it (:func:`alphafence.onboard.decode.path_breaches`)."""
    from alphafence.onboard.corridor import flight_path_from_plan
    from alphafence.onboard.decode import path_breaches

    bad = path_breaches(items, flight_path_from_plan(plan))
    if bad:
        where = ", ".join("home" if k == 0 else f"position {k}" for k in bad[:8])
        err_console.print(f"[yellow]warning:[/] {plan}: {where} breach the fence as the vehicle "
                          "reads it (it would refuse to arm there, or act on its fence in flight)",
                          soft_wrap=True)  # fmt: skip


async def _union(vehicle, options, inclusions):
    """Set FENCE_OPTIONS' union bit after the fence of ``inclusions`` inclusion areas is
    uploaded (until then the vehicle's stricter reading, their intersection, holds)."""
    from alphafence.vehicle.params import ParamError, set_union

    try:
        got = await set_union(vehicle, options)
    except ParamError as exc:
        raise VehicleError(
            f"the fence is uploaded, but {exc}: the vehicle reads its {inclusions} inclusion "
            "areas as their intersection (it must stay inside all of them)"
        ) from None
    out_console.print(
        f"FENCE_OPTIONS={got.values['FENCE_OPTIONS']:g} set and read back: the vehicle reads "
        f"its {inclusions} inclusion areas as their union"
    )


async def _storage(args, vehicle, items, profile):
    """Check (and with ``--reboot``, set) the vehicle's BRD_SD_FENCE for ``items``."""
    from alphafence.vehicle.sd_fence import StorageTooSmall, ensure_fence_storage

    try:
        got = await ensure_fence_storage(
            vehicle, items, profile.sd_fence_kb, args.reboot, say=out_console.print
        )
    except StorageTooSmall as exc:
        raise VehicleError(f"{exc}, or upload with --reboot") from None
    if got.set_kb is None:
        need = f"needs {got.need_kb} kB" if got.need_kb else "fits the board's own storage"
        out_console.print(f"BRD_SD_FENCE is {got.have_kb} kB on the vehicle; this fence {need}")
