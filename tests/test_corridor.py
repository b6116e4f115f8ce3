"""Mission-sized onboard fences: the compiler picks the fences within the selection distance of
the mission's flight path (its legs in order, the way back included), not of a box around it,
and spends the storage where the path runs close to a fence. Checked with real geometry in an
independent frame (tests.helpers.VerifyFrame) on a scene built for it: detailed fences beside
the legs, fences at the corridor's edge, fences inside the mission's convex hull but far from
every leg, and one fence only the way back passes."""

import itertools
import math

import numpy as np
import pytest
import shapely
from hypothesis import event, given, settings
from hypothesis import strategies as st

from alphafence.fencefiles import qgc_plan as plan
from alphafence.fencefiles.fence_geojson import FenceRecord, read_fences
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences
from alphafence.onboard.corridor import Corridor, flight_path, flight_path_from_plan, overshoot
from alphafence.onboard.merge import _greedy, upgrade
from alphafence.onboard.options import Option, Piece

from .helpers import VerifyFrame
from .test_compile import contained, onboard_geometry, validate_like_ardupilot

LON0, LAT0 = 14.5, 35.9
FRAME = LocalFrame(LON0, LAT0)
DISTANCE = 600.0
HOME, A, B = (0.0, 0.0), (3000.0, 0.0), (3000.0, 3000.0)  # out along y=0, up x=3000, RTL home


def ell(cx, cy, size, angle):
    """An L-shaped block with dented sides (24 vertices), ``size`` metres across."""
    s = size
    corners = np.array([(0, 0), (s, 0), (s, 0.3 * s), (0.35 * s, 0.3 * s), (0.35 * s, s), (0, s)])
    ring = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        normal = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
        for t in (0.0, 0.25, 0.5, 0.75):
            ring.append(a + (b - a) * t + (normal * 0.03 * s if t == 0.5 else 0.0))
    c, si = math.cos(angle), math.sin(angle)
    ring = (np.asarray(ring) - s / 2) @ np.array([[c, si], [-si, c]])
    return shapely.Polygon(ring + (cx, cy))


def scene():
    """(kind, metric polygon) of the scene's keep-out fences."""
    out = [
        ("near", ell(x, 150 if k % 2 else -150, 200, 0.3 * k))
        for k, x in enumerate((400, 1100, 1800, 2500))
    ]
    out += [("near", ell(3150, y, 200, 0.5 + 0.3 * k)) for k, y in enumerate((600, 1500, 2400))]
    # 640 m out: only their inner corners reach into the 600 m corridor
    out += [("edge", ell(x, -640, 150, 0.2 * k)) for k, x in enumerate(np.linspace(200, 2800, 7))]
    out += [("edge", ell(3640, y, 150, 0.2 * k)) for k, y in enumerate(np.linspace(300, 2700, 6))]
    # inside the convex hull of the mission's positions, more than 600 m from every leg
    hull = [(2100, 900), (2300, 750), (2250, 1050), (1950, 700)]
    out += [("hull", ell(x, y, 120, k)) for k, (x, y) in enumerate(hull)]
    out.append(("back", ell(1300, 1700, 150, 1.0)))  # ~250 m from the way back only
    return out


def records_of(shapes):
    return [
        FenceRecord(f"{kind}/{k}", "keep_out", FRAME.geom_to_wgs84(g))
        for k, (kind, g) in enumerate(shapes)
    ]


def wgs(points):
    x, y = np.asarray(points, float).T
    lon, lat = FRAME.to_wgs84(x, y)
    return [(float(a), float(b)) for a, b in zip(lon, lat)]


def write_mission(path, points, rtl=True):
    lonlat = wgs(points)
    items = plan.mission_items(lonlat, 30.0, fly_back=False)
    if not rtl:
        items = items[:-1]
    path.write_text(plan.dumps(plan.plan_document([], lonlat[0], items)))
    return path


def added_in_corridor(result, records, path_lonlat, verify):
    """Airspace within DISTANCE of the path that the uploaded items forbid and the
    full-resolution fences do not, and the airspace the fences forbid there (m², verify
    frame, from the items alone)."""
    polys, discs = onboard_geometry(result.items, verify)
    onboard = shapely.union_all(
        polys + [shapely.Point(x, y).buffer(r, quad_segs=64) for x, y, r in discs]
    )
    full = shapely.union_all([verify.local(r.geometry) for r in records])
    corridor = verify.local(shapely.LineString(path_lonlat)).buffer(DISTANCE, quad_segs=32)
    return (
        shapely.difference(onboard, full).intersection(corridor).area,
        full.intersection(corridor).area,
    )


def test_flight_path_is_the_legs_in_order_with_the_way_back(tmp_path):
    mission = write_mission(tmp_path / "m.plan", [HOME, A, B])
    path = flight_path_from_plan(mission)
    assert path.geom_type == "LineString"
    np.testing.assert_allclose(shapely.get_coordinates(path), wgs([HOME, A, B, HOME]), atol=1e-7)
    no_rtl = flight_path_from_plan(write_mission(tmp_path / "n.plan", [HOME, A, B], rtl=False))
    np.testing.assert_allclose(shapely.get_coordinates(no_rtl), wgs([HOME, A, B]), atol=1e-7)
    assert flight_path(wgs([HOME, HOME])).geom_type == "Point"


def test_the_path_corridor_beats_the_convex_hull_on_the_same_budget(tmp_path):
    shapes = scene()
    records = records_of(shapes)
    kinds = {f"{kind}/{k}": kind for k, (kind, _) in enumerate(shapes)}
    path = flight_path_from_plan(write_mission(tmp_path / "m.plan", [HOME, A, B]))
    hull = shapely.MultiPoint(wgs([HOME, A, B])).convex_hull
    on_path = compile_fences(records, path, PROFILES["copter"], distance_m=DISTANCE)
    on_hull = compile_fences(records, hull, PROFILES["copter"], distance_m=DISTANCE)
    for r in (on_path, on_hull):
        assert len(r.items) <= 70 and r.bytes_used <= 560
        validate_like_ardupilot(r.items)

    # fences beyond the distance of every leg but inside the hull: left out on the path only
    hull_ids = {s for s, k in kinds.items() if k == "hull"}
    assert hull_ids <= set(on_path.dropped)
    assert not hull_ids & set(on_hull.dropped)
    assert {s for p in on_hull.pieces for s in p.sources} >= hull_ids

    # every fence reaching into the corridor is stored, and contains what it stands for
    verify = VerifyFrame(LON0, LAT0)
    corridor = verify.local(path).buffer(DISTANCE)
    polys, discs = onboard_geometry(on_path.items, verify)
    for r in records:
        local = verify.local(r.geometry)
        if local.distance(verify.local(path)) <= DISTANCE - 1:
            assert r.site_id not in on_path.dropped
            assert contained(local, polys, discs), r.site_id
        elif local.distance(verify.local(path)) > DISTANCE + 1:
            assert r.site_id in on_path.dropped
    assert corridor.area > 0

    # the bytes go where the path runs close: beside the legs, polygons; at the edge, cheap
    stored = {p.sources[0]: p for p in on_path.pieces if len(p.sources) == 1}
    near = [s for s, k in kinds.items() if k == "near"]
    edge = [s for s, k in kinds.items() if k == "edge" and s not in on_path.dropped]
    assert all(s in stored and stored[s].chosen.kind == "polygon" for s in near)
    near_bytes = np.mean([stored[s].chosen.bytes for s in near])
    edge_bytes = [stored[s].chosen.bytes if s in stored else 0 for s in edge]  # 0: merged
    assert near_bytes > 2 * np.mean(edge_bytes)

    # so the onboard fence takes less airspace around the path than the hull selection's
    path_lonlat = wgs([HOME, A, B, HOME])
    added_path, fenced = added_in_corridor(on_path, records, path_lonlat, verify)
    added_hull, _ = added_in_corridor(on_hull, records, path_lonlat, verify)
    assert added_path < 0.8 * added_hull
    # and the compile's own report agrees with the independent measure
    assert on_path.overshoot.ratio == pytest.approx(added_path / fenced, rel=0.03)
    assert on_path.corridor.of_path and not on_hull.corridor.of_path


def test_the_way_back_counts(tmp_path):
    records = records_of(scene())
    back = next(r.site_id for r in records if r.site_id.startswith("back/"))
    with_rtl = flight_path_from_plan(write_mission(tmp_path / "m.plan", [HOME, A, B]))
    without = flight_path_from_plan(write_mission(tmp_path / "n.plan", [HOME, A, B], rtl=False))
    kept = compile_fences(records, with_rtl, PROFILES["copter"], distance_m=DISTANCE)
    left = compile_fences(records, without, PROFILES["copter"], distance_m=DISTANCE)
    assert back not in kept.dropped and any(back in p.sources for p in kept.pieces)
    assert back in left.dropped


def test_a_box_is_its_own_corridor():
    records = records_of(scene())
    box = shapely.box(*np.ravel(wgs([(-100, -100), (3100, 100)])))
    result = compile_fences(records, box, PROFILES["copter"], distance_m=300)
    corridor = result.corridor
    assert not corridor.of_path
    assert corridor.area.area == pytest.approx(
        corridor.path.buffer(300).area, rel=1e-9
    ) and corridor.path.area == pytest.approx(3200 * 200, rel=0.01)
    stored = {s for p in result.pieces for s in p.sources}
    for r in records:
        far = result.frame.geom_to_local(r.geometry).distance(corridor.path) > 300
        assert (r.site_id in result.dropped) == far and (r.site_id in stored) != far


def test_overshoot_counts_only_the_corridor():
    corridor = Corridor.around(shapely.LineString([(0, 0), (100, 0)]), 10.0)
    fence = shapely.box(40, -5, 60, 5)
    onboard = shapely.box(40, -50, 60, 5)  # 20 x 5 more inside the corridor, 20 x 40 beyond
    o = overshoot(corridor, ([onboard], []), ([fence], []))
    assert o.added_m2 == pytest.approx(100.0, rel=1e-6)
    assert o.fenced_m2 == pytest.approx(200.0) and o.ratio == pytest.approx(0.5, rel=1e-6)
    nothing = overshoot(corridor, ([], []), ([], []))
    assert nothing.fenced_m2 == 0 and math.isnan(nothing.ratio)


def test_compile_cli_reports_the_corridor_and_draws_it(tmp_path, capsys):
    from alphafence.cli import main

    records = records_of(scene())
    fences = tmp_path / "f.geojson"
    _write_geojson(fences, records)
    mission = write_mission(tmp_path / "m.plan", [HOME, A, B])
    out, png = tmp_path / "o.plan", tmp_path / "o.png"
    code = main(
        ["compile", str(fences), "--area", str(mission), "--distance", "600", "-o", str(out)]
        + ["--figure", str(png)]
    )
    assert code == 0
    text = capsys.readouterr().out.replace("\n", " ")
    assert "corridor within 600 m of the flight path" in text and "overshoot" in text
    assert png.stat().st_size > 10_000
    assert len(read_fences(fences)) == len(records)
    assert (
        main(["compile", str(fences), "--area", str(mission), "--distance", "-5", "-o", str(out)])
        == 2
    )


def _write_geojson(path, records):
    import json

    feats = [
        {
            "type": "Feature",
            "properties": {"site_id": r.site_id, "kind": r.kind, "margin_m": 0.0},
            "geometry": shapely.geometry.mapping(r.geometry),
        }
        for r in records
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))


# -- the allocation ----------------------------------------------------------------------


@st.composite
def option_sets(draw):
    """Pieces with ArduPilot-priced options: a circle (1 item, 13 bytes) and polygons of n
    vertices (n items, 2 + 8n bytes), each losing less than the cheaper ones."""
    pieces = []
    for k in range(draw(st.integers(1, 5))):
        sizes = sorted(draw(st.sets(st.integers(3, 12), max_size=3)))
        shapes = ([(1, 13)] if draw(st.booleans()) or not sizes else []) + [
            (n, 2 + 8 * n) for n in sizes
        ]
        losses = sorted(
            draw(st.lists(st.floats(0, 1e4), min_size=len(shapes), max_size=len(shapes))),
            reverse=True,
        )
        opts = [
            Option("circle" if n == 1 else "polygon", n, b, loss, None)
            for (n, b), loss in zip(shapes, losses)
        ]
        pieces.append(Piece([f"p{k}"], False, None, opts))
    return pieces


@settings(max_examples=300, deadline=None)
@given(option_sets(), st.integers(1, 40), st.integers(13, 300))
def test_allocation_is_optimal(pieces, budget_items, budget_bytes):
    """Brute force over every combination: the allocation loses the least area in budget."""
    if sum(p.options[0].items for p in pieces) > budget_items or (
        sum(p.options[0].bytes for p in pieces) > budget_bytes
    ):
        event("the cheapest options do not fit")
        return  # the merging before it guarantees the cheapest options fit
    best = min(
        sum(o.loss for o in combo)
        for combo in itertools.product(*(p.options for p in pieces))
        if sum(o.items for o in combo) <= budget_items
        and sum(o.bytes for o in combo) <= budget_bytes
    )
    upgrade(pieces, budget_items, budget_bytes)
    event("items bind" if budget_items * 8 < budget_bytes else "bytes bind")
    assert sum(p.chosen.items for p in pieces) <= budget_items
    assert sum(p.chosen.bytes for p in pieces) <= budget_bytes
    assert sum(p.chosen.loss for p in pieces) == pytest.approx(best, abs=1e-6)


def test_the_allocation_affords_what_the_greedy_choice_does_not():
    # an airport whose circle -> polygon step needs 69 bytes, and two small fences whose 13 -> 34
    # byte steps save more per byte: the greedy choice spends the budget on those, and the
    # 27 bytes left buy nothing
    def pieces():
        airport = Piece(
            ["airport"],
            False,
            None,
            [Option("circle", 1, 13, 600_000.0, None), Option("polygon", 10, 82, 480_000.0, None)],
        )
        small = [
            Piece(
                [f"s{k}"],
                False,
                None,
                [Option("circle", 1, 13, 60_000.0, None), Option("polygon", 4, 34, 10_000.0, None)],
            )
            for k in range(2)
        ]
        return [airport, *small]

    greedy, exact = pieces(), pieces()
    _greedy(greedy, 70, 13 * 3 + 69)
    upgrade(exact, 70, 13 * 3 + 69)
    assert exact[0].chosen.kind == "polygon" and greedy[0].chosen.kind == "circle"
    assert sum(p.chosen.loss for p in exact) < sum(p.chosen.loss for p in greedy)
