"""Routing over a national fence file: ``alphafence route`` answers in well under 2 s.

The file is synthetic and deterministic: 800 keep-out fences over a country of 800 x 800 km
(half of them in 12 towns, half scattered), 20 on another continent and one around the
antipode of the country's centre. Five routes of 20 to 60 km cross towns. Each is planned by
a whole ``alphafence route`` process (start-up, reading the file, planning, writing the
mission), timed as the median of three runs; the roadmap is built over the fences of the
corridor around start and goal only (the planner reports how many), and every route's
clearance is measured here, exactly, against every fence of the file.
"""

from __future__ import annotations

import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame

TARGET_S = 2.0
CLEARANCE = 20.0
ROUTES = 5
RUNS = 3
SEED = 11
COUNTRY = LocalFrame(2.5, 46.5)


def _site(rng, x, y, radius):
    k = int(rng.integers(5, 12))
    a = rng.uniform(0.0, 2.0 * np.pi, k)
    r = radius * rng.uniform(0.6, 1.0, k)
    pts = shapely.multipoints(np.column_stack([x + r * np.cos(a), y + r * np.sin(a)]))
    return shapely.convex_hull(pts)


def national(rng):
    """(keep-out polygons in COUNTRY's metres, GeoJSON features of the whole file, towns)."""
    towns = rng.uniform(-350e3, 350e3, size=(12, 2))
    centres = np.vstack(
        [
            towns[rng.integers(0, len(towns), 400)] + rng.normal(0, 5e3, size=(400, 2)),
            rng.uniform(-400e3, 400e3, size=(400, 2)),
        ]
    )
    local = [_site(rng, x, y, rng.uniform(100.0, 1500.0)) for x, y in centres]
    wgs84 = list(COUNTRY.geom_to_wgs84(np.array(local, dtype=object)))
    far = LocalFrame(133.0, -25.0)  # Australia
    wgs84 += [
        far.geom_to_wgs84(shapely.Point(x, y).buffer(500.0))
        for x, y in rng.uniform(-1000e3, 1000e3, size=(20, 2))
    ]
    wgs84.append(shapely.box(-177.55, -46.55, -177.45, -46.45))  # the antipode
    feats = [
        {
            "type": "Feature",
            "properties": {"site_id": f"prison/way/{i}", "kind": "keep_out"},
            "geometry": shapely.geometry.mapping(g),
        }
        for i, g in enumerate(wgs84)
    ]
    return np.array(local, dtype=object), feats, towns


def _pairs(rng, local, towns):
    """Start and goal 20 to 60 km apart across a town, each 500 m from every fence."""
    tree = shapely.STRtree(local)
    out = []
    while len(out) < ROUTES:
        c = towns[len(out) % len(towns)]
        half = rng.uniform(10e3, 30e3)
        a = rng.uniform(0, np.pi)
        d = half * np.array([np.cos(a), np.sin(a)])
        ends = np.array([c - d, c + d])
        if tree.query(shapely.points(ends), predicate="dwithin", distance=500.0).size:
            continue
        out.append(ends)
    return out


def _clearance(path_lonlat, local):
    """Least distance from the path to the country's fences (the far ones are thousands of
    km away), in a frame around the path."""
    frame = LocalFrame.around_coords(path_lonlat)
    fences = frame.geom_to_local(COUNTRY.geom_to_wgs84(local))
    x, y = frame.to_local(path_lonlat[:, 0], path_lonlat[:, 1])
    xy = np.column_stack([x, y])
    legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    tree = shapely.STRtree(fences)
    _, d = tree.query_nearest(legs, return_distance=True, all_matches=False)
    return float(d.min())


def run(Row):
    """Five ``alphafence route`` processes over the national file: the slowest median."""
    rng = np.random.default_rng(SEED)
    local, feats, towns = national(rng)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        fences = Path(d) / "national.geojson"
        fences.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
        walls, counts, clear, lengths = [], [], [], []
        for ends in _pairs(rng, local, towns):
            lon, lat = COUNTRY.to_wgs84(ends[:, 0], ends[:, 1])
            plan = Path(d) / "m.plan"
            cmd = [sys.executable, "-m", "alphafence", "route", str(fences), "--one-way"]
            cmd += ["--from", f"{lat[0]:.8f},{lon[0]:.8f}", "--to", f"{lat[1]:.8f},{lon[1]:.8f}"]
            cmd += ["-o", str(plan), "--clearance", f"{CLEARANCE:g}"]
            times = []
            for _ in range(RUNS):
                t = time.perf_counter()
                done = subprocess.run(cmd, capture_output=True, text=True, check=True)
                times.append(time.perf_counter() - t)
            walls.append(statistics.median(times))
            counts += [int(n) for n in re.findall(r"corridor \d+: (\d+) of", done.stdout)]
            items = json.loads(plan.read_text())["mission"]["items"]
            path = np.array([(it["params"][5], it["params"][4]) for it in items[:-1]])
            clear.append(_clearance(path, local))
            lengths.append(float(np.hypot(*(ends[1] - ends[0]))))
    worst = max(walls)
    rows.append(
        Row(
            f"route national file: {len(local)} keep-out fences over 800 km, 21 far away; "
            f"{ROUTES} routes of {min(lengths) / 1e3:.0f}-{max(lengths) / 1e3:.0f} km, whole "
            f"process (median of {RUNS}); roadmaps of at most {max(counts)} fences",
            f"max {worst:.2f} s (median {statistics.median(walls):.2f} s)",
            f"< {TARGET_S:g} s",
            f"a roadmap of all {len(local)} fences",
            f"{max(counts) / len(local):.2f}x the fences",
            worst < TARGET_S,
        )
    )
    rows.append(
        Row(
            "route national file: exact distance of every route to every fence",
            f"min {min(clear):.2f} m",
            f">= {CLEARANCE:g} m",
            "",
            "",
            min(clear) >= CLEARANCE,
        )
    )
    return rows


if __name__ == "__main__":
    from bench.build_bench import Row

    for row in run(Row):
        print(row)
