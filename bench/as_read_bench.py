"""Fences as they are read, on a national-scale synthetic set: how far any zone plus its margin
reaches beyond its fence when the fence is read as ArduPilot reads it (straight lon/lat edges
on its 1e-7 degree integers; ``tests/ardupilot_model.py``, geodesic distances), and how much
larger than their zones the fences are.

The set is synthetic and deterministic: border strips of 100 to 900 km along parallels and
diagonals, military areas (long overlapping strips at 60 to 67°N), regional zones of 20 to 80
km, all with straight lon/lat edges as a national restriction file draws them; margin 100 m.
The peer is the same build with its fences written as they were made in the metric frame
(no densified zones, no held edges): what the kit wrote before it read fences as they are read.
"""

from __future__ import annotations

import sys
import time
from contextlib import ExitStack
from unittest import mock

import numpy as np
import shapely
from pyproj import Geod

from alphafence.fencing import as_read, sites
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.zones.rules import parse_rules

GEOD = Geod(ellps="WGS84")
MARGIN_M = 100.0
SEED = 7


def _strip(lon, lat, az, length, width):
    a = GEOD.fwd(lon, lat, az, length)[:2]
    left = [GEOD.fwd(x, y, az - 90.0, width / 2)[:2] for x, y in ((lon, lat), a)]
    right = [GEOD.fwd(x, y, az + 90.0, width / 2)[:2] for x, y in ((lon, lat), a)]
    return shapely.Polygon([*left, *right[::-1]])


def zones(seed=SEED):
    """The synthetic national set: (name, lon/lat polygon) pairs."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(6):  # border strips
        az = float(rng.choice([90.0, 60.0, 120.0]))
        out.append((f"border/{i}", _strip(5.0 + 3 * i, 46.0 + i, az, rng.uniform(1e5, 9e5),
                                          rng.uniform(2e3, 8e3))))  # fmt: skip
    for i in range(8):  # military strips, overlapping, 60-67 N
        az = float(rng.uniform(40.0, 140.0))
        out.append((f"military/{i}", _strip(12.0 + 1.5 * i, 60.0 + 0.8 * i, az,
                                            rng.uniform(2e5, 6e5), rng.uniform(5e3, 3e4))))  # fmt: skip
    for i in range(16):  # regional zones: simple polygons around a centre
        lon, lat = 2.0 + 1.3 * i, 44.0 + 0.5 * (i % 6)
        poly = None
        while poly is None or not poly.is_valid:
            k = int(rng.integers(6, 16))
            ang = np.sort(rng.uniform(0, 360, k))
            r = rng.uniform(1e4, 4e4, k)
            poly = shapely.Polygon([GEOD.fwd(lon, lat, a, d)[:2] for a, d in zip(ang, r)])
        out.append((f"region/{i}", poly))
    return out


def _features(named, rules):
    from tests.zone_samples import zone_features

    return zone_features([z for _, z in named], rules, "national.geojson")


def _measure(result, named, margin):
    from tests.ardupilot_model import excursion_m

    worst, where = 0.0, ""
    for f in result.fences:
        if f.kind != "keep_out":
            continue
        rings = [np.asarray(p.exterior.coords)[:-1] for p in shapely.get_parts(f.geometry)]
        for s in f.sources:
            name, zone = named[int(s.rsplit("/", 1)[-1])]
            out = excursion_m(zone, rings, margin, spacing_m=50.0, reach_m=200_000.0)
            if out > worst:
                worst, where = out, name
    return worst, where


def _growth(result, named, margin):
    fences = [f for f in result.fences if f.kind == "keep_out"]
    area = sum(f.area_m2 for f in fences)
    zone_area = sum(
        shapely.area(f.frame.read_geom(shapely.union_all([named[int(s.rsplit("/", 1)[-1])][1]
                                                          for s in f.sources])).buffer(margin))
        for f in fences
    )  # fmt: skip
    return area / zone_area, max(f.vertices for f in fences)


def run(Row):
    named = zones()
    rules = parse_rules(
        {
            "defaults": {"point_radius_m": 15.0, "line_width_m": 6.0},
            "rule": [
                {
                    "category": "zone",
                    "kind": "keep_out",
                    "tags": {"restricted": "*"},
                    "margin_m": MARGIN_M,
                }
            ],
        }
    )
    features = _features(named, rules)
    rows = []
    t = time.perf_counter()
    held = build_fences(features, rules, BuildOptions(warn_distance_m=0.0))
    held_s = time.perf_counter() - t
    with ExitStack() as stack:  # the peer: fences written as made in the metric frame
        stack.enter_context(mock.patch.object(sites, "densify_lonlat", lambda g: np.asarray(g)))
        stack.enter_context(
            mock.patch(
                "alphafence.fencing.fences.hold_fences",
                lambda locs, frames, outward=True, regions=None, zones=None: (
                    list(locs),
                    [False] * len(locs),
                ),
            )
        )
        stack.enter_context(mock.patch.object(as_read, "split_lonlat", lambda g: None))
        t = time.perf_counter()
        before = build_fences(features, rules, BuildOptions(warn_distance_m=0.0))
        before_s = time.perf_counter() - t
    worst, where = _measure(held, named, MARGIN_M)
    peer, peer_where = _measure(before, named, MARGIN_M)
    rows.append(
        Row(
            f"as read: worst reach of zone + {MARGIN_M:.0f} m margin beyond its fence "
            f"({len(named)} national zones, ArduPilot's reading)",
            f"{worst:.2f} m" + (f" ({where})" if worst else ""),
            "0 m",
            f"metric-frame fences: {peer:.0f} m ({peer_where})",
            f"build {held_s:.1f} s vs {before_s:.1f} s",
            worst <= 0.01,
        )
    )
    with mock.patch("alphafence.geo.hold._pushed", lambda *a: None):  # edges cut, not moved
        cut = build_fences(features, rules, BuildOptions(warn_distance_m=0.0))
    ratio, most = _growth(held, named, MARGIN_M)
    cut_ratio, cut_most = _growth(cut, named, MARGIN_M)
    rows.append(
        Row(
            "as read: held by moving bowing edges out vs cutting them along their chords",
            f"{ratio:.3f}x the zones' area, {sum(f.vertices for f in held.fences)} vertices",
            "fewer vertices",
            f"cut: {cut_ratio:.3f}x, {sum(f.vertices for f in cut.fences)} vertices",
            f"{sum(f.vertices for f in held.fences) / sum(f.vertices for f in cut.fences):.2f}",
            sum(f.vertices for f in held.fences) <= sum(f.vertices for f in cut.fences),
        )
    )
    for label, opts in (
        ("--max-vertices 32", BuildOptions(warn_distance_m=0.0)),
        ("--max-overshoot 1000", BuildOptions(warn_distance_m=0.0, max_overshoot_m=1000.0)),
    ):
        result = held if opts.max_overshoot_m is None else build_fences(features, rules, opts)
        ratio, most = _growth(result, named, MARGIN_M)
        rows.append(
            Row(
                f"as read: fence area / (zone + margin) area, {label}",
                f"{ratio:.2f}x, at most {most} vertices",
                "stated",
                "-",
                "-",
                True,
            )
        )
    return rows


# bench.without_as_read's build; imported here it would take the as-read work out of this
# process's builds too
WITHOUT_ARGV = [
    sys.executable, "-c", "import sys, bench.without_as_read as w; sys.exit(w.main(sys.argv[1:]))"
]  # fmt: skip
COST_AREAS = 133_000
COST_ROUNDS = 3
COST_TARGET = 1.05


def cost(osm, Row, console):
    """The 133,000-area build (``alphafence build --jobs 2``, pinned to 2 cores) against the
    same build without its as-read work (:mod:`bench.without_as_read`), interleaved, each
    the least of :data:`COST_ROUNDS` runs (other work on the machine only ever adds): CPU
    time of the whole process tree (the work, target <= 1.05x) and wall time."""
    import tempfile
    from pathlib import Path

    from bench.cli_bench import _command
    from bench.scale_bench import CORES, measure
    from bench.synth_db import cached_database

    db, _ = cached_database(osm, COST_AREAS)
    runs = {"with": [], "without": []}
    with tempfile.TemporaryDirectory(prefix="as-read-cost-") as tmp:
        for _ in range(COST_ROUNDS):
            for way, start in (("with", _command()), ("without", WITHOUT_ARGV)):
                out = Path(tmp) / f"{way}.geojson"
                argv = [*start, "build", str(db), "-o", str(out), "-q", "--jobs", str(CORES)]
                m = measure(argv, 300.0, 8e9)
                if m["rc"] or m["why"]:
                    raise RuntimeError(f"{way} as-read: {m['why'] or m['err'][0]}")
                runs[way].append((m["cpu"], m["wall"]))
                console.print(f"as-read cost: {way}: {m['cpu']:.1f} s CPU, {m['wall']:.1f} s wall")
    (cpu, wall), (peer_cpu, peer_wall) = (min(runs[w]) for w in ("with", "without"))
    ratio = cpu / peer_cpu
    return [
        Row(
            f"build of {COST_AREAS:,} areas (--jobs {CORES}) with its as-read work, CPU",
            f"{cpu:.1f} s CPU, {wall:.1f} s wall",
            f"<= {COST_TARGET:g}x without it",
            f"without: {peer_cpu:.1f} s CPU, {peer_wall:.1f} s wall",
            f"{ratio:.2f}x",
            ratio <= COST_TARGET,
            value=cpu,
            unit="s",
            peer_value=peer_cpu,
        )
    ]
