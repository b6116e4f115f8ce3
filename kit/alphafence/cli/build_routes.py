"""The build's other routes. ``alphafence build --source URL``: the zones a live source serves
in an area, fenced one by one, written as the monitor's offline copy (the source, when it was
fetched and its ETag in the output's metadata; each fence naming its zone and version).
``alphafence build ... -o postgresql://...`` and ``--zones-table``: a build written to PostGIS
tables (the fences as the fence file has them; the zones as read), each in one transaction,
after the build has succeeded."""

from __future__ import annotations

import json
import tempfile
from collections import Counter
from pathlib import Path

from rich.markup import escape

from alphafence.cli.common import err_console, out_console
from alphafence.errors import InputError, InputErrors, SourceError, need

NOT_WITH_SOURCE = ("--plan", "--waypoints", "--figure", "--map", "--dask")


def run_source(args, options, source) -> int:
    """Fetch every page, read the zones, fence them, write ``args.output`` all or nothing."""
    import asyncio

    from alphafence.cli.common import SKIP_HINT
    from alphafence.fencing.outputs import build_meta
    from alphafence.sources.answers import read_zones
    from alphafence.zones.features import Database
    from alphafence.zones.rules import load_rules

    if args.databases:
        raise InputError("--source", "reads the zones from the source: give no database too")
    if args.zones_table:
        raise InputError("--zones-table", "the zones are the source's own: not with --source")
    for flag in NOT_WITH_SOURCE:
        if getattr(args, flag[2:].replace("-", "_"), None):
            raise InputError(flag, "is not written with --source: build the fence file, then "
                             "draw or convert it from there")  # fmt: skip
    need(("aiohttp", "--source"), ("scipy", "fencing zones"))
    rules = load_rules(args.rules)
    answer = asyncio.run(_fetch(source, args.bbox))
    if not answer.complete:
        raise SourceError(answer.url, f"incomplete answer, nothing written: {answer.error}")
    zones, bad = read_zones(answer.url, answer.features, rules)
    invalid = []
    if bad and not zones:
        raise SourceError(answer.url, f"none of its {answer.count} features is a zone, nothing "
                          f"written (the first: {_problem(bad[0])})")  # fmt: skip
    if bad and not args.skip_invalid:
        faults = [InputError(answer.url, _problem(line)) for line in bad]
        raise faults[0] if len(faults) == 1 else InputErrors(answer.url, faults, SKIP_HINT)
    for line in bad:
        invalid.append({"file": answer.url, "airspace": None, "line": None, "problem": line})
    if zones and not any(z.restricted or z.fence for z in zones):
        raise InputError(answer.url, f"serves no restricted zone in the area ({len(zones)} "
                         f"zones, rules: {rules.source})")  # fmt: skip
    db = Database([f for z in zones for f in z.restricted], [answer.url], [], Counter(),
                  args.bbox, [], invalid)  # fmt: skip
    meta = build_meta(db, rules, options)
    meta["source"] = answer.metadata()
    count = _write(args.output, zones, rules, options, meta)
    if not args.quiet:
        for entry in invalid:
            err_console.print(
                f"[yellow]note:[/] left out (--skip-invalid): {escape(entry['problem'])}"
            )
        if not zones:
            err_console.print(f"note: {answer.url} serves no zone in the area (a complete, empty "
                              "answer): the copy holds none, and the monitor starts from it")  # fmt: skip
        out_console.print(
            f"{len(zones)} zones from {answer.url} ({answer.pages} pages, fetched "
            f"{answer.fetched_utc}): {count} fences; wrote {args.output}"
        )
    return 0


def _problem(line: str) -> str:
    """A reading's line less its leading URL (the error names the source once)."""
    return line.split(": ", 1)[-1]


async def _fetch(options, bbox):
    from alphafence.sources.ogc import fetch, session

    async with session(options) as http:
        return await fetch(http, options, bbox)


def _write(output, zones, rules, options, meta) -> int:
    """The fences of every zone, written to ``output`` (a fence GeoJSON file, or a PostGIS
    table); how many."""
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencefiles.fence_geojson import dumps
    from alphafence.fencing.zone_fences import zone_fence_features
    from alphafence.sources.postgis import is_postgis_url, write_features

    fenced = zone_fence_features(zones, rules, options)
    features = [f for z in zones for f in fenced[z.hash]]
    if is_postgis_url(output):
        write_features(output, features, meta)
        return len(features)
    if not str(output).lower().endswith((".geojson", ".json")):
        raise InputError(output, "with --source the output is a fence GeoJSON file or a "
                         "postgresql:// table")  # fmt: skip
    from alphafence import __version__

    doc = {"type": "FeatureCollection", "generator": f"alphafence {__version__}",
           "alphafence": meta, "features": features}  # fmt: skip
    write_all({output: dumps(doc)})
    return len(features)


def run_postgis(args, build) -> int:
    """Build as ``build(args)`` does into a temporary fence file, then write the tables."""
    from alphafence.errors import need
    from alphafence.sources.postgis import is_postgis_url, split_target, write_feature_lines

    target, zones = args.output, args.zones_table
    for url in (target, zones):
        if url and is_postgis_url(url):
            split_target(url)  # a malformed URL is said before the build
    need(("psycopg", f"writing {target if is_postgis_url(target) else zones}"))
    with tempfile.TemporaryDirectory(prefix="alphafence-") as tmp:
        if is_postgis_url(target):
            args.output = args.hidden_output = str(Path(tmp) / "fences.geojsonl")
            args.store_output = target  # what an update store names as its fences
        args.zones_table = None
        try:
            status = build(args)
        finally:
            args.output, args.zones_table, args.hidden_output = target, zones, None
        if status:
            return status
        if is_postgis_url(target):
            path, meta, count = Path(tmp) / "fences.geojsonl", {}, [0]

            def lines():  # streamed from the file as written, parsed by PostgreSQL
                with open(path, encoding="utf-8") as fh:
                    for line in fh:
                        if not count[0]:  # the build's meta rides on the first record
                            meta.update(json.loads(line).get("alphafence") or {})
                        count[0] += 1
                        yield line

            version = write_feature_lines(target, lines(), meta)
            if not args.quiet:
                out_console.print(f"wrote {count[0]} fences to {target} (version {version})")
    if zones:
        count = _write_zones(args, zones)
        if not args.quiet:
            out_console.print(f"wrote {count} zones to {zones}")
    return 0


def _write_zones(args, url) -> int:
    import shapely

    from alphafence.sources.postgis import write_features
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    rules = load_rules(args.rules)
    db = read_database(args.databases, rules, args.bbox, bbox_name="--bbox",
                       skip_invalid=args.skip_invalid)  # fmt: skip
    features = []
    for f in db.features:
        props = {"site_id": f.source, "name": f.name, "category": f.category, "kind": f.kind,
                 "margin_m": f.rule.margin_m, "alt_min_m": f.alt_min_m, "alt_max_m": f.alt_max_m,
                 "tags": f.tags, "zone": f.properties or None}  # fmt: skip
        geometry = json.loads(shapely.to_geojson(f.geometry))
        features.append({"type": "Feature", "properties": props, "geometry": geometry})
    write_features(url, features, {"inputs": db.files, "rules": rules.source})
    return len(features)
