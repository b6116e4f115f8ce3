"""Where zones come from: the database files of ``build`` and ``compare`` and their grouping
options, and the live-source options of ``build`` and ``monitor`` (``--source URL`` and how to
ask it)."""

from __future__ import annotations

import argparse

from alphafence.cli.options import at_least, bbox, figure_wants, non_negative, positive

MIB = 2**20


def add_source_options(p, monitor: bool = False) -> None:
    """Add ``--source`` and its options to the sub-parser ``p`` (with ``monitor``, also how
    often it is asked in flight)."""
    g = p.add_argument_group("live source (OGC API - Features)")
    g.add_argument(
        "--source",
        metavar="URL",
        help="an OGC API - Features collection of zones (https://host/collections/ID: ED-318 "
        "zones, or GeoJSON read by --rules), asked for the area that matters"
        + (
            " every --refresh seconds in flight"
            if monitor
            else " (--bbox); the output "
            "records the source, when it was fetched and its ETag: the monitor's offline copy"
        ),
    )
    g.add_argument(
        "--source-token-file",
        metavar="FILE",
        help="a bearer token for the source, the file's first line (default: the "
        "ALPHAFENCE_SOURCE_TOKEN environment variable, if set)",
    )
    g.add_argument(
        "--source-ca-file",
        metavar="PEM",
        help="trust only these CA certificates for the source's TLS (default: the system's)",
    )
    g.add_argument(
        "--source-timeout",
        type=positive("--source-timeout", "seconds"),
        default=10.0,
        metavar="S",
        help="seconds for one request, connection to last byte (default 10)",
    )
    g.add_argument(
        "--source-origin",
        action="append",
        metavar="URL",
        help="another origin (https://host:port) the source's next links and redirects may "
        "lead to, its token sent there too (repeatable; default: the source's own alone, any "
        "other refused)",
    )
    g.add_argument(
        "--source-max-bytes",
        type=positive("--source-max-bytes", "MiB"),
        default=32.0,
        metavar="MIB",
        help="one answer's budget over all its pages, inflated (default 32 MiB; past it the "
        "answer is incomplete: it writes nothing, removes nothing)",
    )
    g.add_argument(
        "--source-max-features",
        type=at_least("--source-max-features", 1),
        default=20_000,
        metavar="N",
        help="one answer's budget of features (default 20,000; past it, as for bytes)",
    )
    if not monitor:
        return
    g.add_argument(
        "--refresh",
        type=positive("--refresh", "seconds"),
        default=30.0,
        metavar="S",
        help="ask the source every S seconds (default 30)",
    )
    g.add_argument(
        "--stale-after",
        type=positive("--stale-after", "seconds"),
        metavar="S",
        help="without a good answer for S seconds the source is stale, said to the ground "
        "station (default: 3 refreshes); the zones in force stay",
    )
    g.add_argument(
        "--source-radius",
        type=positive("--source-radius", "metres"),
        default=5000.0,
        metavar="M",
        help="ask for the zones within M metres of the vehicle and of each mission waypoint "
        "(default 5000)",
    )
    g.add_argument("--rules", metavar="FILE", help="rules TOML for the source's GeoJSON zones")


def source_options(args):
    """The :class:`~alphafence.sources.ogc.SourceOptions` of the parsed flags (None without
    ``--source``); a token file that cannot be read is one line."""
    if not getattr(args, "source", None):
        return None
    from alphafence.errors import InputError
    from alphafence.sources.ogc import MAX_PAGE_BYTES, SourceOptions, read_token
    from alphafence.sources.request import origin

    if not origin(args.source):
        raise InputError("--source", f"{args.source!r} is not an http:// or https:// URL")
    also = tuple(getattr(args, "source_origin", None) or ())
    for url in also:
        if not origin(url):
            raise InputError("--source-origin", f"{url!r} is not an http:// or https:// origin")
    budget = int(args.source_max_bytes * MIB)
    return SourceOptions(
        args.source,
        token=read_token(args.source_token_file),
        ca_file=args.source_ca_file,
        timeout_s=args.source_timeout,
        max_bytes=min(MAX_PAGE_BYTES, budget),
        max_answer_bytes=budget,
        max_features=args.source_max_features,
        also_origins=also,
    )


def source_line(event) -> str:
    """One line for a live source's event (``monitor`` prints it).

    Examples
    --------
    >>> source_line({"event": "source_zone", "zone": "Z1", "name": "fire", "change": "new",
    ...              "kinds": ["keep_out", "warning"], "window": "active"})
    'zone new: fire (keep_out, warning; active)'
    """
    kind, zone = event["event"], event.get("name") or event.get("zone") or ""
    if kind == "source_answer":
        if event.get("not_modified"):
            return f"source: unchanged ({event['seconds']} s)"
        done = "complete" if event["complete"] else "INCOMPLETE"
        return (f"source: {event['zones']} zones, {event['invalid']} not zones, "
                f"{event['pages']} pages, {done}, {event['seconds']} s")  # fmt: skip
    if kind == "source_zone":
        return f"zone {event['change']}: {zone} ({', '.join(event['kinds'])}; {event['window']})"
    if kind == "source_zone_window":
        return f"zone {zone}: {event['window']}"
    if kind == "source_fences":
        return f"fences swapped in: {event['fences']} ({event.get('live', 0)} from the source)"
    detail = event.get("error") or event.get("problem") or event.get("reason") or ""
    return f"{kind} {zone} {detail}".strip()


def live_options(args):
    """The monitor's :class:`~alphafence.monitor.live.LiveOptions` (None without
    ``--source``)."""
    source = source_options(args)
    if source is None:
        if args.rules:
            from alphafence.errors import InputError

            raise InputError("--rules", "reads the source's zones: add --source URL")
        return None
    from alphafence.errors import need

    need(("aiohttp", "--source"), ("scipy", "--source (zones are fenced in flight)"))
    from alphafence.fencing.pipeline import BuildOptions
    from alphafence.monitor.live import LiveOptions
    from alphafence.zones.rules import load_rules

    return LiveOptions(
        source,
        load_rules(args.rules),
        BuildOptions(),
        refresh_s=args.refresh,
        stale_after_s=args.stale_after,
        radius_m=args.source_radius,
        trusted_keys=trusted_keys(args),
        from_file=getattr(args, "fences", None) is not None,
    )


def with_source(args, records) -> list:
    """``records`` and, with ``--source``, the fences of the source's zones around the
    operating area (``--area``'s flight path or ``--bbox``, widened by ``--distance``),
    fetched whole or not at all: ``compile`` and ``upload``."""
    source = source_options(args)
    if source is None:
        return records
    import asyncio

    import shapely

    from alphafence.errors import InputError, InputErrors, SourceError, need
    from alphafence.fencing.zone_fences import read_answer, unpack
    from alphafence.geo.frame import LocalFrame
    from alphafence.onboard.corridor import flight_path_from_plan
    from alphafence.sources.ogc import fetch, session
    from alphafence.zones.rules import load_rules

    need(("aiohttp", "--source"), ("scipy", "--source (its zones are fenced here)"))
    area = flight_path_from_plan(args.area) if args.area else shapely.box(*args.bbox)
    frame = LocalFrame(*shapely.centroid(area).coords[0])
    x0, y0, x1, y1 = shapely.bounds(frame.geom_to_local(shapely.envelope(area))).tolist()
    pad = float(getattr(args, "distance", 0.0) or 0.0) + 100.0
    lons, lats = frame.to_wgs84([x0 - pad, x1 + pad], [y0 - pad, y1 + pad])
    bbox = (float(min(lons)), float(min(lats)), float(max(lons)), float(max(lats)))

    async def ask():
        async with session(source) as http:
            return await fetch(http, source, bbox)

    answer = asyncio.run(ask())
    if not answer.complete:
        raise SourceError(answer.url, f"incomplete answer, nothing compiled: {answer.error}")
    from alphafence.fencing.pipeline import BuildOptions

    _, bad, fenced = read_answer(answer.url, answer.features, load_rules(), BuildOptions(), set())
    if bad:
        faults = [InputError(answer.url, line.split(": ", 1)[-1]) for line in bad]
        raise faults[0] if len(faults) == 1 else InputErrors(answer.url, faults)
    return list(records) + unpack(answer.url, [p for packed in fenced.values() for p in packed])


def trusted_keys(args) -> tuple:
    """The public keys a document source's signature is checked against: ``--trusted-key``
    and ``ALPHAFENCE_TRUSTED_KEYS``, as for the fences' own file."""
    import os

    env = os.environ.get("ALPHAFENCE_TRUSTED_KEYS", "")
    return tuple(getattr(args, "trusted_key", None) or ()) + tuple(
        k for k in env.split(os.pathsep) if k
    )


def add_database_options(p: argparse.ArgumentParser, optional: bool = False) -> None:
    """Add the geofence database and site-grouping options of ``build`` and ``compare``.

    Their values become ``args.databases``, ``args.rules``, ``args.bbox``, ``args.join``,
    ``args.margin``, ``args.max_vertices`` and ``args.max_overshoot``; :func:`build_options` turns them into the
    library's :class:`~alphafence.fencing.pipeline.BuildOptions`.
    """
    p.add_argument(
        "databases",
        nargs="*" if optional else "+",
        metavar="DATABASE",
        help="geofence database(s): .osm.pbf, .osm, GeoJSON or ED-269 JSON",
    )
    p.add_argument("--rules", metavar="FILE", help="rules TOML (default: the shipped rules)")
    p.add_argument(
        "--bbox",
        metavar="MINLON,MINLAT,MAXLON,MAXLAT",
        type=bbox,
        help="only features intersecting this box",
    )
    p.add_argument(
        "--join",
        type=non_negative("--join", "metres"),
        default=25.0,
        metavar="M",
        help="features of one category within M metres form one site (default 25)",
    )
    p.add_argument(
        "--margin",
        type=non_negative("--margin", "metres"),
        default=None,
        metavar="M",
        help="override every rule's margin (0 = the paper's setting)",
    )
    p.add_argument(
        "--max-vertices",
        type=at_least("--max-vertices", 4),
        default=32,
        metavar="N",
        help="vertex budget per fence polygon (default 32)",
    )
    p.add_argument(
        "--max-overshoot",
        type=non_negative("--max-overshoot", "metres"),
        default=None,
        metavar="M",
        help="no simplified fence reaches more than M metres beyond the shape its method "
        "draws (alpha shape, hull): large sites take more vertices than --max-vertices "
        "where needed (default: the vertex budget alone)",
    )


def build_wants(databases, figure=None):
    """What ``build`` and ``compare`` need beyond the base install, as
    :func:`alphafence.errors.need` takes it: pyosmium for OSM files, scipy to build fences,
    matplotlib to draw ``figure``."""
    from alphafence.zones.database import osm_wants

    return [*osm_wants(databases), ("scipy", "building fences"), *figure_wants(figure)]


def build_options(args):
    """The :class:`~alphafence.fencing.pipeline.BuildOptions` of :func:`add_database_options`'s
    values, and of ``build``'s ``--method``, ``--alpha-radius`` and ``--warn-distance`` where
    the verb has them."""
    from alphafence.fencing.pipeline import BuildOptions

    return BuildOptions(
        method=getattr(args, "method", "alpha"),
        alpha_radius=getattr(args, "alpha_radius", None),
        max_vertices=args.max_vertices,
        warn_distance_m=getattr(args, "warn_distance", 30.0),
        margin_m=args.margin,
        max_overshoot_m=getattr(args, "max_overshoot", None),
        join_m=args.join,
    )


def start_fences(args):
    """``monitor``'s fences to start from: ``--fences``' (checked as trusted); with
    ``--source`` an empty file, or none (a set of no fence: the source's first fences get a
    frame of their own)."""
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.cli.common import check_trust
    from alphafence.errors import InputError
    from alphafence.geo.frame import LocalFrame

    if args.fences is None:
        if not args.source:
            raise InputError("--fences", "give the fences to watch, or --source URL (zones from "
                             "a live source alone)")  # fmt: skip
        return FenceSet([], frame=LocalFrame(0.0, 0.0))
    check_trust(args, args.fences)
    return FenceSet.from_geojson(args.fences, empty_ok=bool(args.source))
