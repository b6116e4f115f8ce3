"""Compile fences into ArduPilot's small fence storage.

ArduPilot keeps fences in a few hundred bytes (Copter: 560 bytes, at most 70 items): a
polygon costs 2 + 8 bytes a vertex (one item a vertex), a circle 13 bytes (one item), the
return point 9, plus a 4-byte header and a 1-byte end marker. The compiler picks the fences
near the operating area and chooses, per fence, a circle or a polygon of k vertices, each
simplified *outward* (keep-out) or *inward* (keep-in) so the onboard fence still contains
(or stays inside) the fence it stands for, to lose the least area within the budget. When
even the cheapest choice does not fit, the nearest fences are merged (an alpha shape of the
two). Coordinates are rounded to MAVLink's 1e-7 degrees here, and every emitted polygon is
re-checked after rounding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
import shapely.errors

from alphafence.build.fences import circle_polygon, enclosing_circle
from alphafence.errors import InputError
from alphafence.geo.alpha import alpha_shape, outer_polygons
from alphafence.geo.coords import from_e7, to_e7
from alphafence.geo.frame import LocalFrame
from alphafence.geo.outward import simplify_polygon
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)
from alphafence.mavlink.storage import (
    CIRCLE_BYTES,
    END_BYTES,
    HEADER_BYTES,
    RETURN_BYTES,
    Profile,
    polygon_bytes,
    storage_bytes,
)

PAD_M = 0.05  # onboard fences stand this far outside what they must contain (1e-7 deg < 1.2 cm)
# vertex counts tried per fence (69 and 83 fill a Copter's and a Plane's storage alone)
K_CANDIDATES = (
    4,
    5,
    6,
    7,
    8,
    9,
    10,
    11,
    12,
    14,
    16,
    18,
    20,
    24,
    28,
    32,
    36,
    40,
    44,
    48,
    52,
    56,
    60,
    64,
    69,
    76,
    83,
    96,
    128,
    160,
    192,
    224,
    255,
)


@dataclass
class Option:
    kind: str  # "circle" | "polygon"
    items: int
    bytes: int
    loss: float  # m² added (keep-out) or removed (keep-in) relative to the fence
    local: object  # metric polygon (a circumscribed polygon for circles)
    circle: tuple | None = None  # (x, y, r) metric

    @property
    def label(self):
        return "circle" if self.kind == "circle" else f"{self.items}-gon"


@dataclass
class Piece:
    sources: list
    inclusion: bool
    local: object  # the metric polygon the onboard item(s) must contain (or stay inside)
    options: list
    choice: int = 0
    merged: bool = False
    outward: bool | None = None  # None: outward for keep-out, inward for keep-in

    @property
    def grows(self) -> bool:
        return (not self.inclusion) if self.outward is None else self.outward

    @property
    def chosen(self) -> Option:
        return self.options[self.choice]


@dataclass
class CompileResult:
    items: list
    pieces: list
    profile: Profile
    frame: LocalFrame
    dropped: list = field(default_factory=list)  # fences far from the area (not compiled)
    merges: list = field(default_factory=list)  # [(sources...)] merged to fit
    return_point: tuple | None = None

    @property
    def bytes_used(self) -> int:
        return storage_bytes(self.items)

    @property
    def loss_m2(self) -> float:
        return sum(p.chosen.loss for p in self.pieces)


def _pareto(options):
    """Options by increasing cost, each strictly better (less loss) than the cheaper ones."""
    options.sort(key=lambda o: (o.items, o.bytes, o.loss))
    out = []
    for o in options:
        if not out or o.loss < out[-1].loss - 1e-9:
            out.append(o)
    return out


def piece_options(poly, inclusion: bool, max_vertices: int, circle=None):
    """The ways one fence polygon can be stored, cheapest first."""
    if inclusion:
        inner = shapely.buffer(poly, -PAD_M, join_style="mitre")
        base = outer_polygons(inner)
        base = base[int(np.argmax(shapely.area(base)))] if len(base) else poly
    else:
        base = outer_polygons(shapely.buffer(poly, PAD_M, join_style="mitre", mitre_limit=10.0))[0]
    area = poly.area
    opts = []
    if not inclusion:
        c = circle if circle is not None else enclosing_circle(base)
        c = (c[0], c[1], c[2] + PAD_M) if circle is not None else c
        opts.append(
            Option("circle", 1, CIRCLE_BYTES, math.pi * c[2] ** 2 - area, circle_polygon(*c), c)
        )
    n = len(base.exterior.coords) - 1
    ks = sorted({k for k in K_CANDIDATES if k < n} | ({n} if n <= max_vertices else set()))
    for k in ks:
        if k > max_vertices:
            break
        simp = simplify_polygon(base, k, 0.0, outward=not inclusion) if k < n else base
        v = len(simp.exterior.coords) - 1
        if v > max_vertices or v < 3:
            continue
        loss = (area - simp.area) if inclusion else (simp.area - area)
        opts.append(Option("polygon", v, polygon_bytes(v), max(loss, 0.0), simp))
    return _pareto(opts)


def operating_area_from_plan(path):
    """The operating area of a mission (.plan or waypoint file): the convex hull of the
    positions it flies through, home included; and its first position."""
    from alphafence.formats.mission import read_mission

    pts = [(w.lon, w.lat) for w in read_mission(path, min_positions=1)]
    return shapely.MultiPoint(pts).convex_hull, pts[0]


def compile_fences(
    records,
    area,
    profile: Profile,
    distance_m=2000.0,
    keep_in_m=None,
    return_point=None,
    max_items=None,
) -> CompileResult:
    """Fences (alphafence.formats.fence_geojson.FenceRecord) near ``area`` (WGS84) -> onboard items."""
    frame = LocalFrame.around(area)
    area_local = frame.geom_to_local(area)
    if max_items is not None:
        profile = Profile(
            profile.name, min(profile.items, max_items), profile.bytes, profile.max_polygon_vertices
        )
    pieces, dropped = [], []
    for rec in records:
        if rec.kind not in ("keep_out", "keep_in"):
            continue
        local = frame.geom_to_local(rec.geometry)
        if not local.is_valid:
            # a ring that projects to a self-touching one: keep all of it, spikes included
            local = shapely.buffer(shapely.make_valid(local), 1e-3, join_style="mitre")
        if shapely.distance(local, area_local) > distance_m:
            dropped.append(rec.site_id)
            continue
        circle = None
        if rec.circle is not None:
            x, y = frame.to_local(rec.circle[0], rec.circle[1])
            circle = (float(x), float(y), rec.circle[2])
        for part in outer_polygons(local):
            opts = piece_options(part, rec.kind == "keep_in", profile.max_polygon_vertices, circle)
            if opts:
                pieces.append(Piece([rec.site_id], rec.kind == "keep_in", part, opts))
    fixed_items, fixed_bytes = 0, HEADER_BYTES + END_BYTES
    if return_point is not None:
        fixed_items += 1
        fixed_bytes += RETURN_BYTES
    if keep_in_m is not None:
        allowed = outer_polygons(shapely.buffer(area_local, keep_in_m))[0]
        # the operator's area: stored generously (outward), never inside what they asked for
        opts = [
            o
            for o in piece_options(allowed, False, profile.max_polygon_vertices)
            if o.kind == "polygon"
        ]
        keep = Piece(
            ["operating-area"],
            True,
            allowed,
            [min(opts, key=lambda o: (o.items > 8, o.loss))],
            outward=True,
        )
        keep.options[0].loss = 0.0
        pieces.insert(0, keep)
    budget_items = profile.items - fixed_items
    budget_bytes = profile.bytes - fixed_bytes
    merges = []
    _fit_by_merging(pieces, budget_items, budget_bytes, profile, merges)
    _upgrade(pieces, budget_items, budget_bytes)
    _merge_to_upgrade(pieces, budget_items, budget_bytes, profile, merges)
    items = _emit(pieces, frame, return_point)
    result = CompileResult(items, pieces, profile, frame, dropped, merges, return_point)
    used = storage_bytes(items)
    if len(items) > profile.items or used > profile.bytes:  # pragma: no cover - guarded above
        raise InputError(
            "compile", f"internal error: {len(items)} items / {used} bytes exceed {profile.name}"
        )
    return result


def _totals(pieces):
    return sum(p.chosen.items for p in pieces), sum(p.chosen.bytes for p in pieces)


def _cheapest_circle(piece):
    c = piece.options[0].circle
    if c is None:
        c = enclosing_circle(piece.local)
    return c


def _best_merge(pieces, neighbours=4):
    """The pair of neighbouring keep-out pieces whose merge adds the least area, estimated
    as the larger of what their convex hull adds (large pieces stay polygons) and what
    their common circle adds (small pieces end up as circles)."""
    outs = [i for i, p in enumerate(pieces) if not p.inclusion]
    if len(outs) < 2:
        return None
    geoms = np.array([pieces[i].local for i in outs], dtype=object)
    k = min(neighbours + 1, len(outs))
    pairs = set()
    for a in range(len(outs)):
        d = shapely.distance(geoms[a], geoms)
        for b in np.argsort(d)[:k]:
            if a != b:
                pairs.add((min(a, int(b)), max(a, int(b))))
    a, b = np.array(sorted(pairs)).T
    hulls = shapely.convex_hull(geoms)
    both = shapely.convex_hull(
        np.array(
            [shapely.GeometryCollection([geoms[i], geoms[j]]) for i, j in zip(a, b)], dtype=object
        )
    )
    hull_cost = shapely.area(both) - shapely.area(hulls[a]) - shapely.area(hulls[b])
    # small pieces end up as circles: what their common circle adds counts too
    c = np.array([_cheapest_circle(pieces[i]) for i in outs])
    x, y, r = c[:, 0], c[:, 1], c[:, 2]
    d = np.hypot(x[a] - x[b], y[a] - y[b])
    big = np.maximum(r[a], r[b])
    R = np.where(d + np.minimum(r[a], r[b]) <= big, big, (d + r[a] + r[b]) / 2)
    circle_cost = np.pi * (R**2 - r[a] ** 2 - r[b] ** 2)
    cost = np.maximum(hull_cost, circle_cost)
    j = int(np.argmin(cost))
    return float(cost[j]), outs[a[j]], outs[b[j]]


def _merge(pieces, a, b, profile, merges):
    pair = shapely.GeometryCollection([pieces[a].local, pieces[b].local])
    try:
        joined, _ = alpha_shape(shapely.union(pieces[a].local, pieces[b].local))
    except shapely.errors.GEOSException:
        joined = None
    if joined is None or joined.geom_type != "Polygon":  # not joined into one piece: the hull
        joined = shapely.convex_hull(pair)
    merged = Piece(
        pieces[a].sources + pieces[b].sources,
        False,
        joined,
        piece_options(joined, False, profile.max_polygon_vertices),
        merged=True,
    )
    merges.append(tuple(merged.sources))
    pieces[a] = merged
    del pieces[b]


def _fit_by_merging(pieces, budget_items, budget_bytes, profile, merges):
    while True:
        items, nbytes = _totals(pieces)
        if items <= budget_items and nbytes <= budget_bytes:
            return
        best = _best_merge(pieces)
        if best is None:
            raise InputError(
                "compile",
                f"the fences near the area do not fit a {profile.name} "
                f"({items} items / {nbytes} bytes for {budget_items} / {budget_bytes})",
            )
        _merge(pieces, best[1], best[2], profile, merges)


def _merge_to_upgrade(pieces, budget_items, budget_bytes, profile, merges, rounds=40):
    """Merge two small neighbours when the storage it frees buys a larger saving elsewhere
    (typically: two substations share a circle so the airport keeps its shape)."""
    for _ in range(rounds):
        best = _best_merge(pieces)
        if best is None:
            return
        trial = [
            Piece(p.sources, p.inclusion, p.local, p.options, p.choice, p.merged, p.outward)
            for p in pieces
        ]
        before = sum(p.chosen.loss for p in pieces)
        trial_merges = []
        _merge(trial, best[1], best[2], profile, trial_merges)
        _upgrade(trial, budget_items, budget_bytes)
        after = sum(p.chosen.loss for p in trial)
        if after >= before:
            return
        pieces[:] = trial
        merges.extend(trial_merges)


def _upgrade(pieces, budget_items, budget_bytes):
    """Greedy multiple-choice knapsack: spend the budget where it saves most area."""
    while True:
        items, nbytes = _totals(pieces)
        best = None
        for p in pieces:
            cur = p.chosen
            for j in range(p.choice + 1, len(p.options)):
                o = p.options[j]
                di, db = o.items - cur.items, o.bytes - cur.bytes
                if items + di > budget_items or nbytes + db > budget_bytes:
                    continue
                gain = cur.loss - o.loss
                cost = di / budget_items + db / budget_bytes
                ratio = gain / cost if cost > 0 else math.inf
                if gain > 0 and (best is None or ratio > best[0]):
                    best = (ratio, p, j)
        if best is None:
            return
        best[1].choice = best[2]


def _round_lonlat(frame, xy):
    lon, lat = frame.to_wgs84(np.asarray(xy)[:, 0], np.asarray(xy)[:, 1])
    lon = np.array([from_e7(to_e7(v)) for v in np.atleast_1d(lon)])
    lat = np.array([from_e7(to_e7(v)) for v in np.atleast_1d(lat)])
    return lon, lat


def _emit(pieces, frame, return_point):
    items = []
    if return_point is not None:
        items.append(
            FenceItem(
                RETURN_POINT, 0.0, from_e7(to_e7(return_point[0])), from_e7(to_e7(return_point[1]))
            )
        )
    for p in sorted(pieces, key=lambda p: (not p.inclusion, p.chosen.kind == "circle")):
        o = p.chosen
        if o.kind == "circle":
            x, y, r = o.circle
            lon, lat = _round_lonlat(frame, [(x, y)])
            items.append(
                FenceItem(
                    CIRCLE_EXCLUSION,
                    float(math.ceil(r * 100) / 100 + 0.01),
                    float(lon[0]),
                    float(lat[0]),
                )
            )
            continue
        ring = shapely.LinearRing(o.local.exterior)
        pts = np.asarray(ring.coords)[:-1]
        if not ring.is_ccw:
            pts = pts[::-1]
        lon, lat = _round_lonlat(frame, pts)
        check = shapely.Polygon(np.column_stack(frame.to_local(lon, lat)))
        ok = check.is_valid and (check.covers(p.local) if p.grows else p.local.covers(check))
        if not ok:
            raise InputError(
                "compile",
                f"fence {', '.join(p.sources)}: rounding to 1e-7 degrees broke "
                "containment; please report this",
            )
        cmd = POLYGON_INCLUSION if p.inclusion else POLYGON_EXCLUSION
        items.extend(FenceItem(cmd, float(len(pts)), float(a), float(b)) for a, b in zip(lon, lat))
    return items
