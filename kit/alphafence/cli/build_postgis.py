"""``alphafence build ... -o postgresql://...`` and ``--zones-table``: a build written to
PostGIS tables (the fences as the fence file has them; the zones as read), each in one
transaction, after the build has succeeded."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from alphafence.cli.common import out_console


def run_postgis(args, build) -> int:
    """Build as ``build(args)`` does into a temporary fence file, then write the tables."""
    from alphafence.errors import need
    from alphafence.sources.postgis import is_postgis_url, split_target, write_features

    target, zones = args.output, args.zones_table
    for url in (target, zones):
        if url and is_postgis_url(url):
            split_target(url)  # a malformed URL is said before the build
    need(("psycopg", f"writing {target if is_postgis_url(target) else zones}"))
    with tempfile.TemporaryDirectory(prefix="alphafence-") as tmp:
        if is_postgis_url(target):
            args.output = args.hidden_output = str(Path(tmp) / "fences.geojson")
        args.zones_table = None
        try:
            status = build(args)
        finally:
            args.output, args.zones_table, args.hidden_output = target, zones, None
        if status:
            return status
        if is_postgis_url(target):
            doc = json.loads((Path(tmp) / "fences.geojson").read_text(encoding="utf-8"))
            version = write_features(target, doc["features"], doc.get("alphafence"))
            if not args.quiet:
                out_console.print(f"wrote {len(doc['features'])} fences to {target} "
                                  f"(version {version})")  # fmt: skip
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
