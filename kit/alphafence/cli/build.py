"""alphafence build: read a geofence database, group sites, write fences."""

from __future__ import annotations

import os

from rich.table import Table

from alphafence.cli.common import (
    SKIP_HINT,
    callback,
    err_console,
    out_console,
    progress,
    union_hint,
)
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.options import at_least, non_negative, positive
from alphafence.cli.source_options import (
    add_database_options,
    add_source_options,
    build_options,
    build_wants,
    source_options,
)
from alphafence.errors import need
from alphafence.fencing import METHODS


def register(sub):
    """Add the ``build`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "build",
        help="build fences from a geofence database",
        description="Build alpha-shape (or polygon, circle, exact) fences around restricted sites.",
    )
    add_database_options(p, optional=True)
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FENCES.geojson",
        help="the fences: GeoJSON (lon, lat), .geojsonl, .parquet, or a PostGIS table "
        "postgresql://USER@HOST:PORT/DATABASE/SCHEMA.TABLE (its rows replaced in one "
        "transaction, for an OGC API server to serve)",
    )
    p.add_argument(
        "--zones-table",
        metavar="postgresql://.../SCHEMA.TABLE",
        help="also write the restricted zones read to this PostGIS table",
    )
    p.add_argument(
        "--plan", metavar="FILE.plan", help="also write a QGroundControl plan (geoFence)"
    )
    p.add_argument(
        "--waypoints", metavar="FILE.waypoints", help="also write an ArduPilot fence waypoint file"
    )
    p.add_argument("--figure", metavar="MAP.png", help="also draw the fences on a map")
    add_map_options(p)
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
    p.add_argument(
        "--jobs",
        type=jobs_count,
        default="auto",
        metavar="N",
        help="worker processes fencing tiles; auto: every core for a database of 5,000 "
        "restricted features or more (or over 32 MiB of files), else 1 (this process), as "
        "starting workers costs more than fencing fewer",
    )
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="fence the tiles on a dask.distributed cluster (e.g. tcp://10.0.0.5:8786); "
        "needs the dask extra here and on the workers (pip install '.[dask]' in the "
        "AlphaFence checkout)",
    )
    p.add_argument(
        "--tile-size",
        type=positive("--tile-size", "degrees"),
        default=0.25,
        metavar="DEG",
        help="tile edge in degrees (default 0.25); sites never split at tile edges",
    )
    p.add_argument(
        "--skip-invalid",
        action="store_true",
        help="leave out the zones that cannot be read as areas (OpenAir airspaces, KML "
        "placemarks, ED-269/ED-318 zones, GeoJSON features; each is named in the summary and "
        "the output's metadata) instead of failing with the list of them",
    )
    p.add_argument(
        "--store",
        metavar="FILE.sqlite",
        help="also keep what 'alphafence update' needs to apply OpenStreetMap's changes to "
        "these fences (the restricted features, the extract's nodes and ways) in this file",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    add_source_options(p)
    p.set_defaults(func=run)


def jobs_count(text: str):
    """argparse type of ``--jobs``: ``auto`` (None: chosen by the database's size, see
    :func:`alphafence.fencing.tiled.auto_jobs`) or an integer of at least 1.

    Examples
    --------
    >>> jobs_count("auto"), jobs_count("3")
    (None, 3)
    """
    return None if text.strip().lower() == "auto" else at_least("--jobs", 1)(text)


def run(args) -> int:
    """Read the databases as a stream, fence them tile by tile, write the outputs as tiles
    complete (all or nothing); exit status 0."""
    from alphafence.errors import InputError
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencefiles.fence_stream import writer_for
    from alphafence.fencing.outputs import build_meta
    from alphafence.sources.postgis import is_postgis_url
    from alphafence.zones.database import DatabaseStream
    from alphafence.zones.rules import load_rules

    source = source_options(args)
    if source is not None:
        from alphafence.cli.build_routes import run_source

        return run_source(args, build_options(args), source)
    if not args.databases:
        raise InputError("build", "give a geofence database, or --source URL")
    if is_postgis_url(args.output) or args.zones_table:
        from alphafence.cli.build_routes import run_postgis

        return run_postgis(args, run)
    wants = build_wants(args.databases, args.figure)
    if args.dask:
        wants.append(("distributed", f"--dask {args.dask}"))
    if writer_for(args.output).suffixes == (".parquet",):
        wants.append(("pyarrow", f"writing {args.output}"))
    need(*wants)
    check_map_args(args)
    rules = load_rules(args.rules)
    opts = build_options(args)
    stream = DatabaseStream(
        args.databases, rules, args.bbox, bbox_name="--bbox", skip_invalid=args.skip_invalid
    )
    try:
        stream.read_ahead()  # what it leaves out goes in the outputs' metadata
    except InputError as exc:
        raise _hinted(exc) from None
    meta = build_meta(stream.database(), rules, opts)
    keep = bool(args.plan or args.waypoints or args.figure or args.map)
    store = None
    if args.store:
        from alphafence.updating.keep import StoreWriter

        target = getattr(args, "store_output", None) or args.output
        store = StoreWriter(args.store, args.databases, rules, args.rules, opts, args.bbox,
                            target)  # fmt: skip
    try:
        result, extra = _build(args, stream, rules, opts, meta, keep, store)
    except InputError as exc:
        if store is not None:
            store.abort()
        raise _hinted(exc) from None
    except BaseException:
        if store is not None:
            store.abort()
        raise
    if store is not None:
        with progress(not args.quiet) as prog:
            tick = callback(prog, f"keeping {args.databases[0]}'s nodes and ways for updates")
            store.finish(None if tick is None else lambda n: tick(n, None))
    write_all(extra)
    if extra:
        from alphafence.mavlink.items import fence_items

        union_hint(fence_items(result.fences))
    # a PostGIS build's temporary file is not named: its table is, once written
    written = [
        str(w) for w in [args.output, *extra] if str(w) != getattr(args, "hidden_output", None)
    ] + ([f"{args.store} (for alphafence update)"] if store is not None else [])
    if args.figure:
        from alphafence.plots.fences import fence_map

        fence_map(
            result.fences,
            result.site_objects,
            args.figure,
            title=f"AlphaFence: {opts.method} fences",
            note=meta.get("attribution"),
        )
        written.append(args.figure)
    if args.map:
        from alphafence.cli.maps import write_map_page
        from alphafence.plots.webmap import fence_layers, restricted_layer

        layers = [restricted_layer(result.site_objects), *fence_layers(result.fences)]
        title = f"AlphaFence: {opts.method} fences ({len(result.fences)})"
        written.append(write_map_page(args, title, layers, note=meta.get("attribution")))
    if not args.quiet:
        summary(stream.database(), result, opts, written)
    return 0


def phases(prog, what):
    """A ``progress(phase, done, total)`` callback for :func:`build_tiled`: features read,
    then features fenced of all, with counts and rates."""
    if prog is None:
        return None
    tasks = {}

    def update(phase, done, total):
        if phase not in tasks:
            for task in tasks.values():
                prog.stop_task(task)
            label = f"reading {what}" if phase == "reading" else "fencing tiles"
            tasks[phase] = prog.add_task(label, total=total)
        prog.update(tasks[phase], completed=done, total=total)

    return update


def summary(db, result, opts, written):
    """Print the fences built per category and kind, and notes on repairs, skipped features
    and what does not fit a vehicle."""
    from rich.markup import escape

    from alphafence.fencing.tiled import LOOSE, median_of
    from alphafence.mavlink.items import MAX_POLYGON_VERTICES
    from alphafence.mavlink.storage import PROFILES

    copter_items = PROFILES["copter"].items
    stats = result.stats
    seconds = sum(result.seconds.values())
    table = Table(
        title=f"{result.sites} sites from {result.features} restricted features "
        f"({opts.method} fences, {result.jobs} tile job(s), {seconds:.2f} s)"
    )
    for col in ("category", "kind", "sites", "fences", "vertices (median / max)", "area km²"):
        table.add_column(col, justify="right" if col not in ("category", "kind") else "left")
    for (cat, kind), (count, area, vertices) in sorted(stats.by_kind.items()):
        table.add_row(
            cat,
            kind,
            str(result.site_kinds.get((cat, kind), "")),
            str(count),
            f"{median_of(vertices):.0f} / {max(vertices)}",
            f"{area / 1e6:.3f}",
        )
    out_console.print(table)
    notes = list(db.notes)
    for zone in db.invalid:
        name = f"airspace {zone['airspace']!r}" if zone["airspace"] else ""
        name += ", " if name and zone["line"] else ""
        where = f"{zone['file']}: {name}" + (f"line {zone['line']}" if zone["line"] else "")
        notes.append(f"left out (--skip-invalid): {where}: {zone['problem']}")
    if db.repaired:
        shown = ", ".join(db.repaired[:5]) + (" ..." if len(db.repaired) > 5 else "")
        notes.append(f"repaired {len(db.repaired)} invalid (self-intersecting) polygon(s): {shown}")
    for reason, n in db.skipped.items():
        if reason.startswith("all of "):  # a database that adds nothing: said as such
            notes.append(f"{reason[len('all of ') :]}; nothing was taken from it")
        else:
            notes.append(f"skipped {n} feature(s): {reason}")
    if stats.repaired_count:
        notes.append(
            f"{stats.repaired_count} fence(s) re-united with their site after a containment "
            f"check: {', '.join(stats.repaired[:5])}"
        )
    if stats.oversized_count:
        notes.append(
            f"{stats.oversized_count} polygon(s) exceed ArduPilot's {MAX_POLYGON_VERTICES} "
            f"vertices: {', '.join(stats.oversized[:3])}"
        )
    if stats.loose_count:
        growth, site = stats.loose[0]
        bound = "" if opts.max_overshoot_m is not None else "; --max-overshoot M bounds it"
        notes.append(
            f"{stats.loose_count} fence(s) cover more than {LOOSE:.0f}x their restricted area "
            f"plus margin (most: {site}, {growth:.0f}x) at --max-vertices {opts.max_vertices}"
            f"{bound}"
        )
    if stats.items > copter_items:
        notes.append(
            f"{stats.items} fence items: more than a Copter holds ({copter_items}); "
            "compile an onboard subset for the operating area before uploading"
        )
    for n in notes:  # names read from the files are text, not rich markup
        err_console.print(f"[yellow]note:[/] {escape(n)}")
    if written:
        out_console.print("wrote " + ", ".join(written))


def _build(args, stream, rules, opts, meta, keep, store=None):
    """The build, its fence file written as tiles complete: ``(result, the other outputs
    rendered)``."""
    from alphafence.fencefiles.fence_stream import open_writers
    from alphafence.fencing.outputs import render
    from alphafence.fencing.tiled import build_tiled

    with progress(not args.quiet) as prog, open_writers([args.output], meta) as writers:
        result = build_tiled(
            stream,
            rules,
            opts,
            writers=writers,
            jobs=args.jobs,
            dask=args.dask,
            keep=keep,
            progress=phases(prog, ", ".join(args.databases)),
            tile_deg=args.tile_size,
            # the spool (an unlinked file, gone with the process) sits beside the output, on
            # its disk: /tmp is often memory (tmpfs), and a country's features are gigabytes
            spool_dir=os.path.dirname(os.path.abspath(args.output)),
            on_features=None if store is None else store.add,
        )
        extra = render(result.fences, meta, None, args.plan, args.waypoints) if keep else {}
    return result, extra


def _hinted(exc):
    """``exc``, with what ``--skip-invalid`` would do when it lists several faults (an OpenAir
    file's, one or more) and each is a zone it leaves out; a single fault stays one line."""
    from alphafence.errors import InputErrors

    faults = exc.errors if isinstance(exc, InputErrors) else [exc]
    if not isinstance(exc, InputErrors) and not hasattr(exc, "airspace"):
        return exc  # one bad zone, one line
    if not all(hasattr(f, "airspace") or getattr(f, "skippable", False) for f in faults):
        return exc
    return InputErrors(exc.path, faults, SKIP_HINT)
