"""One position check's p99 against Malta's fences, 100,000 and 1,000,000 synthetic fences,
side by side with the paper's way (a plain loop of shapely contains per fence), and as a ratio
to a calibration measured in the same run, the same way: the p99 of making one shapely point
(the least a check does; the ratio says how the check scales on a machine of another speed).
Target: at 1,000,000 fences the full check's p99 under 1 ms."""

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


def calibration_us(positions) -> float:
    """The p99 of making one shapely point, timed as a check is."""
    return _p99_us(lambda x, y: shapely.points((x, y)), positions)


def _compare(label, fs, positions, peer_positions, Row, target_us=None):
    fs.index()
    calib = calibration_us(positions)
    ours = _p99_us(lambda x, y: fs.check(x, y, 30.0, 7.0, 7.0, 150.0), positions)
    n = len(fs.records)
    if peer_positions is None:
        return Row(
            f"position check p99, {label} ({n:,} fences)",
            f"{ours:.0f} us, {ours / calib:.0f}x the calibration ({calib:.1f} us)",
            f"< {target_us:.0f} us", "-", "-", ours < target_us, value=ours, unit="us",
        )  # fmt: skip
    polys = list(
        shapely.from_wkb(shapely.to_wkb(fs.local))
    )  # unprepared, as a plain loop holds them

    def plain(x, y):
        p = shapely.Point(x, y)
        return [poly.contains(p) for poly in polys]

    peer = _p99_us(plain, peer_positions)
    ratio = peer / ours
    return Row(
        f"position check p99, {label} ({n:,} fences)",
        f"{ours:.0f} us, {ours / calib:.0f}x the calibration ({calib:.1f} us)",
        "report (x the calibration)",
        f"plain contains loop {peer / 1e3:.1f} ms",
        f"{ratio:.0f}x",
        True,
        value=ours / calib,
        unit="x the calibration",
    )


def synthetic(n, rng, half_m=50_000.0):
    """``n`` keep-out boxes of 20-200 m scattered over a square ``2 * half_m`` wide."""
    frame = LocalFrame(14.5, 35.9)
    cx, cy = rng.uniform(-half_m, half_m, n), rng.uniform(-half_m, half_m, n)
    size = rng.uniform(20, 200, n)
    boxes = frame.geom_to_wgs84(shapely.box(cx, cy, cx + size, cy + size))
    records = [FenceRecord(f"synthetic/{i}", "keep_out", g) for i, g in enumerate(boxes)]
    return FenceSet(records, frame=frame)


def run(osm, Row, seed=1):
    rng = np.random.default_rng(seed)
    rules = load_rules()
    db = read_database([osm], rules)
    result = build_fences(db.features, rules, BuildOptions())
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    malta = FenceSet(records)
    b = shapely.total_bounds(malta.local)
    pos = np.column_stack([rng.uniform(b[0], b[2], 5000), rng.uniform(b[1], b[3], 5000)])
    rows = [_compare("Malta", malta, pos, pos[:500], Row)]
    many = synthetic(100_000, rng)
    pos = np.column_stack([rng.uniform(-50_000, 50_000, 5000), rng.uniform(-50_000, 50_000, 5000)])
    rows.append(_compare("synthetic", many, pos, pos[:20], Row))
    del many
    # a million over a square 10 times as large: as dense, ten times as many
    half = 50_000.0 * 10**0.5
    pos = np.column_stack([rng.uniform(-half, half, 5000), rng.uniform(-half, half, 5000)])
    rows.append(_compare("synthetic", synthetic(1_000_000, rng, half), pos, None, Row, 1000.0))
    return rows
