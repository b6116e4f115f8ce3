"""Issue 3 target: compiled onboard fences for the Malta airport operating area (5 km around
the aerodrome) within a Copter's 70 items, against the full-resolution alpha fences."""

from __future__ import annotations

import time

from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.mavlink.storage import PROFILES, sd_fence_kb_needed, storage_bytes
from alphafence.onboard.compile import compile_fences
from alphafence.zones.database import read_database
from alphafence.zones.rules import load_rules

AIRPORT = "way/23541031"


def airport_case(osm):
    """Malta's alpha fences, its sites by id, the airport's 5 km area, its keep-out fences and
    their records: what every compile row measures on."""
    rules = load_rules()
    db = read_database([osm], rules)
    result = build_fences(db.features, rules, BuildOptions())
    sites = {s.site_id: s for s in result.sites}
    airport = next(s for s in result.sites if AIRPORT in s.sources)
    area = airport.frame.geom_to_wgs84(airport.geometry.buffer(5000.0))
    keep_out = [f for f in result.fences if f.kind == "keep_out"]
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in keep_out]
    return result, sites, area, keep_out, records


def run(osm, Row):
    result, sites, area, keep_out, records = airport_case(osm)
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


# issue 11: a mission round the airport area at 560 bytes, its fences chosen along its path
MISSION = (  # (lon, lat): the SITL home north of the airport, its west end, its east end, home
    (14.48600, 35.89098),
    (14.44000, 35.85000),
    (14.53000, 35.84500),
    (14.48600, 35.89098),
)
CORRIDOR_DISTANCES = (1000.0, 2000.0)  # --distance; 2000 is the default


def corridor(osm, Row):
    """Onboard overshoot within the corridor of a mission round the Malta airport, at a
    Copter's 560 bytes, against the full-resolution alpha fences, for each distance.

    The mission's legs run from the SITL home north of the airport to its west end, across
    to its east end and back home, each the route planner's (20 m clearance) around the
    fences. Within the corridor (the airspace within ``--distance`` of that path) the onboard
    fence's overshoot is its area outside the restricted areas, relative to the alpha fences'
    area outside them (both contain the restricted areas): 1x means the onboard fence is as
    tight there as the alpha fences. The peer is the former selection, by the convex hull of
    the mission's positions, on the same budget, measured in the same corridor.
    """
    import numpy as np
    import shapely

    from alphafence.onboard.corridor import Corridor, flight_path
    from alphafence.route.planner import FenceRoadmap

    rules = load_rules()
    db = read_database([osm], rules)
    built = build_fences(db.features, rules, BuildOptions())
    sites = {s.site_id: s for s in built.sites}
    keep_out = [f for f in built.fences if f.kind == "keep_out"]
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in keep_out]
    roadmap = FenceRoadmap(records, 20.0, MISSION)
    legs = [roadmap.route(a, b)[1] for a, b in zip(MISSION, MISSION[1:])]
    route = np.concatenate([legs[0]] + [leg[1:] for leg in legs[1:]])
    path = flight_path(route)
    hull = shapely.MultiPoint(route).convex_hull

    def over(compiled, frame, area):
        """(onboard, alpha) area outside the restricted areas within ``area``, m²."""
        ids = {sid for p in compiled.pieces for sid in p.sources}
        restricted = shapely.union_all(
            [frame.geom_to_local(sites[s].frame.geom_to_wgs84(sites[s].geometry)) for s in ids]
        )
        alpha = shapely.union_all(
            [frame.geom_to_local(f.geometry) for f in keep_out if f.site_id in ids]
        )
        onboard = shapely.union_all(
            [
                frame.geom_to_local(compiled.frame.geom_to_wgs84(p.chosen.local))
                for p in compiled.pieces
            ]
        )
        r = restricted.intersection(area).area
        return onboard.intersection(area).area - r, alpha.intersection(area).area - r, len(ids)

    rows = []
    for distance in CORRIDOR_DISTANCES:
        t = time.perf_counter()
        compiled = compile_fences(records, path, PROFILES["copter"], distance_m=distance)
        seconds = time.perf_counter() - t
        frame = compiled.frame
        area = Corridor.around(frame.geom_to_local(path), distance).area
        onboard_over, alpha_over, n = over(compiled, frame, area)
        by_hull = compile_fences(records, hull, PROFILES["copter"], distance_m=distance)
        hull_over, hull_alpha, _ = over(by_hull, frame, area)
        ratio = onboard_over / alpha_over
        rows.append(
            Row(
                f"compile a mission round Malta airport ({len(route)} waypoints, "
                f"{shapely.length(compiled.corridor.path) / 1e3:.1f} km), --distance "
                f"{distance:g}: {n} fences -> {len(compiled.items)} items, "
                f"{storage_bytes(compiled.items)} B, {len(compiled.merges)} merges "
                f"({seconds:.2f} s)",
                f"overshoot in corridor {onboard_over / 1e6:.3f} km² = {ratio:.2f}x alpha",
                "<= 2x alpha, <= 70 items",
                f"alpha {alpha_over / 1e6:.3f} km²; hull selection {hull_over / hull_alpha:.2f}x",
                f"{ratio:.2f}x",
                ratio <= 2.0 and len(compiled.items) <= 70,
            )
        )
    return rows


def navio2(osm, Row):
    """Issue 11 target: the Malta airport area (5 km around the aerodrome, every keep-out fence
    in it) compiled for ``--profile navio2`` (BRD_SD_FENCE = 64 kB): its onboard overshoot
    against the full-resolution alpha fences', at most 1.05x; the peer is the same area in a
    Copter's 560 bytes. Overshoot as in :func:`run`: the stored shapes' area (a circle's
    disc) minus the restricted areas they stand for, over the alpha fences' area minus the
    same."""
    import math

    result, sites, area, keep_out, records = airport_case(osm)
    ratios = {}
    for name in ("navio2", "copter"):
        t = time.perf_counter()
        compiled = compile_fences(records, area, PROFILES[name], distance_m=0.0)
        seconds = time.perf_counter() - t
        ids = {sid for p in compiled.pieces for sid in p.sources}
        restricted = sum(sites[sid].geometry.area for sid in ids)
        alpha_over = sum(f.area_m2 for f in keep_out if f.site_id in ids) - restricted
        onboard = sum(
            p.chosen.local.area if p.chosen.circle is None else math.pi * p.chosen.circle[2] ** 2
            for p in compiled.pieces
        )
        ratios[name] = ((onboard - restricted) / alpha_over, compiled, seconds, len(ids))
    ratio, compiled, seconds, n = ratios["navio2"]
    as_own = sum(
        p.chosen.kind == "polygon"
        and not p.merged
        and (p.chosen.own or p.chosen.items == len(p.local.exterior.coords) - 1)
        for p in compiled.pieces
    )
    kb = sd_fence_kb_needed(compiled.items)
    return [
        Row(
            f"compile Malta airport + 5 km, navio2: {n} fences -> {len(compiled.items)} items, "
            f"{storage_bytes(compiled.items)} B (BRD_SD_FENCE >= {kb}), {as_own} stored as "
            f"themselves, {len(compiled.merges)} merges ({seconds:.2f} s)",
            f"overshoot {ratio:.3f}x alpha",
            "<= 1.05x alpha",
            f"copter 560 B: {ratios['copter'][0]:.2f}x",
            f"{ratio:.3f}x",
            ratio <= 1.05,
        ),
    ]
