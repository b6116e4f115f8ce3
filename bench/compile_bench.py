"""Issue 3 target: compiled onboard fences for the Malta airport operating area (5 km around
the aerodrome) within a Copter's 70 items, against the full-resolution alpha fences."""

from __future__ import annotations

import time

from alphafence.build.pipeline import BuildOptions, build_fences
from alphafence.formats.database import read_database
from alphafence.formats.fence_geojson import FenceRecord
from alphafence.formats.rules import load_rules
from alphafence.mavlink.storage import PROFILES, storage_bytes
from alphafence.onboard.compile import compile_fences

AIRPORT = "way/23541031"


def run(osm, Row):
    rules = load_rules()
    db = read_database([osm], rules)
    result = build_fences(db.features, rules, BuildOptions())
    sites = {s.site_id: s for s in result.sites}
    airport = next(s for s in result.sites if AIRPORT in s.sources)
    area = airport.frame.geom_to_wgs84(airport.geometry.buffer(5000.0))
    keep_out = [f for f in result.fences if f.kind == "keep_out"]
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in keep_out]
    t = time.perf_counter()
    compiled = compile_fences(records, area, PROFILES["copter"], distance_m=0.0)
    seconds = time.perf_counter() - t
    included = {sid for p in compiled.pieces for sid in p.sources}
    restricted = sum(sites[sid].geometry.area for sid in included)
    alpha_area = sum(f.area_m2 for f in keep_out if f.site_id in included)
    onboard_area = sum(
        p.chosen.local.area
        if p.chosen.circle is None
        else 3.141592653589793 * p.chosen.circle[2] ** 2
        for p in compiled.pieces
    )
    alpha_over = alpha_area - restricted
    onboard_over = onboard_area - restricted
    ratio = onboard_over / alpha_over
    return [
        Row(
            f"compile Malta airport + 5 km: {len(included)} fences -> {len(compiled.items)} items, "
            f"{storage_bytes(compiled.items)} B ({seconds:.2f} s)",
            f"overshoot {onboard_over / 1e6:.2f} km²",
            "<= 2x alpha, <= 70 items",
            f"alpha fences {alpha_over / 1e6:.2f} km²",
            f"{ratio:.2f}x",
            ratio <= 2.0 and len(compiled.items) <= 70,
        ),
    ]
