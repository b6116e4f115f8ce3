"""Issue 2 targets: reading Malta, fencing every site, against the alphashape package."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.fencing.compare import compare_methods
from alphafence.fencing.fences import required_region
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.sites import group_sites
from alphafence.geo.alpha import alpha_shape, alpha_shape_points, outer_polygons
from alphafence.zones.database import read_database
from alphafence.zones.rules import load_rules

FIXED_ALPHA_M = 60.0


@dataclass
class Row:
    """One result: the strings the table shows, and optionally the number behind them.

    ``value`` (in ``unit``) and ``peer_value`` (the peer's, in the same unit) are for scripts
    reading ``bench-out/results.json``; ``group`` is set by ``python -m bench`` per group.
    """

    name: str
    result: str
    target: str
    peer: str
    ratio: str
    ok: bool
    value: float | None = None
    unit: str = ""
    peer_value: float | None = None
    group: str = ""


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times), out


def point_sets(sites):
    """The point sets the alpha stage triangulates, in the paper's setting (margin 0; with
    the rules' margins, Malta's sites close into single polygons): the outer-ring vertices
    of each site's region. Returns (site, region, points, parts)."""
    out = []
    for s in sites:
        region = required_region(s.geometry, 0.0)
        polys = outer_polygons(region)
        pts = np.unique(shapely.get_coordinates(shapely.get_exterior_ring(polys)), axis=0)
        if len(pts) >= 3:
            out.append((s, region, pts, len(polys)))
    return out


def peer_optimizealpha():
    """alphashape.optimizealpha, with the one-line shapely 2 fix it needs (it iterates a
    MultiPoint, which shapely 2 spells ``.geoms``); its algorithm is unchanged."""
    import importlib

    import alphashape

    opt = importlib.import_module("alphashape.optimizealpha")

    def _testalpha(points, alpha):
        polygon = alphashape.alphashape(points, alpha)
        if isinstance(polygon, shapely.Polygon):
            return all(polygon.intersects(shapely.Point(p)) for p in points)
        return False

    opt._testalpha = _testalpha
    return opt.optimizealpha


def run(osm, optimize_sites, console):
    import alphashape

    optimizealpha = peer_optimizealpha()

    rows = []
    rules = load_rules()
    t_read, med_read, db = best_of(lambda: read_database([osm], rules))
    rows.append(
        Row(
            "read Malta (pyosmium, default rules)",
            f"{t_read:.3f} s (median {med_read:.3f})",
            "< 1.5 s",
            "-",
            "-",
            t_read < 1.5,
            value=t_read,
            unit="s",
        )
    )

    t_fence, med_fence, result = best_of(lambda: build_fences(db.features, rules, BuildOptions()))
    rows.append(
        Row(
            f"fence {len(result.sites)} Malta sites, auto alpha (+warning layers)",
            f"{t_fence:.3f} s (median {med_fence:.3f})",
            "< 0.5 s",
            "-",
            "-",
            t_fence < 0.5,
            value=t_fence,
            unit="s",
        )
    )

    sites = group_sites(db.features, rules)
    sets = point_sets(sites)
    multi = [x for x in sets if x[3] > 1]
    console.print(
        f"{len(sets)} point sets ({len(multi)} multi-part sites), {sum(len(x[2]) for x in sets)} points"
    )

    t_ours, _, ours = best_of(lambda: [alpha_shape_points(x[2], FIXED_ALPHA_M) for x in sets])
    lists = [[tuple(q) for q in x[2]] for x in sets]
    t_peer, _, theirs = best_of(
        lambda: [alphashape.alphashape(pl, 1.0 / FIXED_ALPHA_M) for pl in lists], repeat=1
    )
    agree = np.mean([abs(a.area - b.area) <= 1e-6 * max(b.area, 1) for a, b in zip(ours, theirs)])
    ratio = t_peer / t_ours
    rows.append(
        Row(
            f"alpha shape at {FIXED_ALPHA_M:g} m on {len(sets)} point sets ({100 * agree:.0f}% same area)",
            f"{1e3 * t_ours:.1f} ms",
            ">= 3x faster",
            f"alphashape {1e3 * t_peer:.0f} ms",
            f"{ratio:.1f}x",
            ratio >= 3,
            value=t_ours,
            unit="s",
            peer_value=t_peer,
        )
    )

    chosen = sorted(multi, key=lambda x: len(x[2]))[: max(1, optimize_sites)]
    t_auto, _, _ = best_of(lambda: [alpha_shape(x[1]) for x in chosen])
    t0 = time.perf_counter()
    for x in chosen:
        optimizealpha([tuple(q) for q in x[2]], silent=True)
    t_opt = time.perf_counter() - t0
    ratio = t_opt / t_auto
    rows.append(
        Row(
            f"automatic alpha per site ({len(chosen)} smallest multi-part sites)",
            f"{1e3 * t_auto / len(chosen):.2f} ms/site",
            ">= 100x faster",
            f"optimizealpha {1e3 * t_opt / len(chosen):.0f} ms/site",
            f"{ratio:.0f}x",
            ratio >= 100,
            value=t_auto / len(chosen),
            unit="s/site",
            peer_value=t_opt / len(chosen),
        )
    )

    for label, margin in (("paper's setting, margin 0", 0.0), ("rules' margins", None)):
        cmp = compare_methods(
            db.features, rules, ["alpha", "polygon"], BuildOptions(margin_m=margin)
        )
        st = {s.method: s for s in cmp.stats}
        a, p = st["alpha"], st["polygon"]
        over = a.overshoot / p.overshoot if margin == 0.0 else a.excess / p.excess
        what = "overshoot" if margin == 0.0 else "excess beyond margin"
        rows.append(
            Row(
                f"alpha {what} vs polygon ({label})",
                f"{(a.overshoot if margin == 0.0 else a.excess):.3f}",
                "<= 40% of polygon",
                f"polygon {(p.overshoot if margin == 0.0 else p.excess):.3f}",
                f"{100 * over:.0f}%",
                over <= 0.40,
                value=a.overshoot if margin == 0.0 else a.excess,
                unit="of the restricted area",
                peer_value=p.overshoot if margin == 0.0 else p.excess,
            )
        )
        rows.append(
            Row(
                f"alpha containment ({label})",
                f"{a.containment_pct:.4f} %",
                "100 %",
                "-",
                "-",
                abs(a.containment_pct - 100) < 1e-6,
                value=a.containment_pct,
                unit="%",
            )
        )
        rows.append(
            Row(
                f"alpha p95 vertices per fence ({label})",
                f"{a.vertices_p95:.0f}",
                "<= 32",
                f"polygon {p.vertices_p95:.0f}",
                "-",
                a.vertices_p95 <= 32,
                value=float(a.vertices_p95),
                unit="vertices",
                peer_value=float(p.vertices_p95),
            )
        )
    return rows
