"""One position check's p99 against Malta's fences (target <= 20 us) and 100,000 fences
(<= 50 us), side by side with the paper's way (a plain loop of shapely contains per fence)."""

from __future__ import annotations

import time

import numpy as np
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.frame import LocalFrame
from alphafence.zones.database import read_database
from alphafence.zones.rules import load_rules


def _p99_us(fn, positions):
    times = np.empty(len(positions))
    for i, (x, y) in enumerate(positions):
        t = time.perf_counter()
        fn(x, y)
        times[i] = time.perf_counter() - t
    return float(np.percentile(times, 99) * 1e6)


def _compare(label, fs, positions, peer_positions, Row, target_us):
    ours = _p99_us(lambda x, y: fs.check(x, y, 30.0, 7.0, 7.0, 150.0), positions)
    polys = list(
        shapely.from_wkb(shapely.to_wkb(fs.local))
    )  # unprepared, as a plain loop holds them

    def plain(x, y):
        p = shapely.Point(x, y)
        return [poly.contains(p) for poly in polys]

    peer = _p99_us(plain, peer_positions)
    ratio = peer / ours
    return Row(
        f"position check p99, {label} ({len(polys)} fences)",
        f"{ours:.0f} us",
        f"<= {target_us:.0f} us",
        f"plain contains loop {peer / 1e3:.1f} ms",
        f"{ratio:.0f}x",
        ours <= target_us,
    )


def run(osm, Row, seed=1):
    rng = np.random.default_rng(seed)
    rules = load_rules()
    db = read_database([osm], rules)
    result = build_fences(db.features, rules, BuildOptions())
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    malta = FenceSet(records)
    b = shapely.total_bounds(malta.local)
    pos = np.column_stack([rng.uniform(b[0], b[2], 5000), rng.uniform(b[1], b[3], 5000)])
    rows = [_compare("Malta", malta, pos, pos[:500], Row, 20.0)]

    frame = LocalFrame(14.5, 35.9)
    n = 100_000
    cx, cy = rng.uniform(-50_000, 50_000, n), rng.uniform(-50_000, 50_000, n)
    size = rng.uniform(20, 200, n)
    boxes = shapely.box(cx, cy, cx + size, cy + size)
    many = FenceSet(
        [
            FenceRecord(f"synthetic/{i}", "keep_out", g)
            for i, g in enumerate(frame.geom_to_wgs84(boxes))
        ],
        frame=frame,
    )
    pos = np.column_stack([rng.uniform(-50_000, 50_000, 5000), rng.uniform(-50_000, 50_000, 5000)])
    rows.append(_compare("synthetic", many, pos, pos[:20], Row, 50.0))
    return rows
