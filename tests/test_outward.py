"""Conservative simplification: outward only adds area, inward only removes it."""

import math

import numpy as np
import shapely
import shapely.affinity
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.geo.outward import simplify_polygon, simplify_ring
from alphafence.geo.outward_many import simplify_polygons


@st.composite
def star_polygons(draw):
    n = draw(st.integers(5, 120))
    ang = np.sort(
        np.asarray(draw(st.lists(st.floats(0, 2 * math.pi), min_size=n, max_size=n, unique=True)))
    )
    radii = np.asarray(draw(st.lists(st.floats(5, 500), min_size=n, max_size=n)))
    poly = shapely.Polygon(np.column_stack([radii * np.cos(ang), radii * np.sin(ang)]))
    return shapely.make_valid(poly) if not poly.is_valid else poly


@settings(max_examples=80, deadline=None)
@given(star_polygons(), st.sampled_from([4, 6, 12, 32]), st.sampled_from([0.0, 1.0, 10.0]))
def test_outward_contains_and_meets_the_budget(poly, budget, tol):
    if poly.geom_type != "Polygon" or poly.area < 1:
        return
    out = simplify_polygon(poly, budget, tol, outward=True)
    assert out.is_valid
    # up to floating-point noise on degenerate (collinear) input; fences carry 0.1 m of
    # slack for that, and each fence is checked exactly against its site afterwards
    assert out.covers(poly) or shapely.difference(poly, out).area <= 1e-9 * poly.area
    assert len(out.exterior.coords) - 1 <= max(budget, len(poly.exterior.coords) - 1)
    assert len(out.exterior.coords) - 1 <= budget


@settings(max_examples=60, deadline=None)
@given(star_polygons(), st.sampled_from([4, 8, 16]))
def test_inward_stays_inside(poly, budget):
    if poly.geom_type != "Polygon" or poly.area < 1:
        return
    out = simplify_polygon(poly, budget, 1.0, outward=False)
    assert out.is_valid and (poly.covers(out) or shapely.difference(out, poly).area < 1e-6)


def test_the_notch_is_filled_first():
    # a square with a shallow notch: filling the notch costs less than cutting a corner
    ring = np.array([(0, 0), (45, 0), (50, 2), (55, 0), (100, 0), (100, 100), (0, 100)], float)
    out = simplify_ring(ring, 4, 0.0)
    assert len(out) == 4
    assert shapely.Polygon(out).equals(shapely.box(0, 0, 100, 100))


def test_orientation_is_kept():
    cw = np.array([(0, 0), (0, 10), (5, 11), (10, 10), (10, 0)], float)
    out = simplify_ring(cw, 4, 0.0)
    assert not shapely.LinearRing(out).is_ccw and shapely.Polygon(out).covers(shapely.Polygon(cw))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(star_polygons(), min_size=1, max_size=12),
    st.sampled_from([4, 8, 32]),
    st.sampled_from([0.0, 1.0, 10.0]),
    st.booleans(),
    st.floats(-1e6, 1e6),
)
def test_many_at_once_are_each_alone(polys, budget, tol, outward, offset):
    """simplify_polygons finds every ring's first operations in one vectorised pass (numpy's
    hypot only sorting out what is clearly too high or too far): the polygons must be those
    simplify_polygon makes one at a time, to the last bit, far from the origin too."""
    import alphafence.geo.outward_many as outward_module

    polys = [shapely.affinity.translate(p, offset, -offset) for p in polys]
    polys = [p for p in polys if p.geom_type == "Polygon"]
    odd = [  # repeated vertices, a hole, heights, no area, nothing
        shapely.Polygon(np.column_stack([np.linspace(0, 1e3, 60), np.r_[0.0, 1e-9 * np.ones(58), 5.0]])),
        shapely.Polygon([(0, 0), (0, 0), (50, 0), (50, 40), (25, 41), (0, 40)],
                        holes=[[(10, 10), (20, 10), (20, 20)]]),
        shapely.Polygon([(0, 0, 1), (50, 0, 1), (50, 40, 2), (25, 41, 2), (0, 40, 3)]),
        shapely.Polygon([(0, 0), (50, 0), (50, 0), (50, 40), (25, 41), (0, 40), (0, 0)]),
        shapely.Polygon([(0, 0), (10, 0), (20, 0), (10, 0)]),
        shapely.Polygon(),
    ]  # fmt: skip
    polys += [shapely.affinity.translate(p, offset, -offset) for p in odd]
    batch_min, outward_module.BATCH_MIN_VERTICES = outward_module.BATCH_MIN_VERTICES, 0
    try:  # the vectorised pass for any number of vertices
        many = simplify_polygons(polys, budget, tol, outward)
    finally:
        outward_module.BATCH_MIN_VERTICES = batch_min
    assert [shapely.to_wkb(p) for p in many] == [
        shapely.to_wkb(simplify_polygon(p, budget, tol, outward)) for p in polys
    ]


def _ops_pass(pts, max_vertices, tolerance):
    """The first operations of a ring as _greedy's own pass finds them, by kind and vertex."""
    from alphafence.geo.outward import _ops

    P = [tuple(p) for p in pts.tolist()]
    reach = 2.0 * float((pts.max(axis=0) - pts.min(axis=0)).max()) + 1.0
    prune = tolerance if len(P) <= max_vertices else math.inf
    heap = []
    for i, p, a, b, q in zip(range(len(P)), P[-1:] + P[:-1], P, P[1:] + P[:1], P[2:] + P[:2]):
        _ops(heap, i, 0, p, a, b, q, reach, prune)
    return sorted(heap, key=lambda op: op[2:4])


@settings(max_examples=80, deadline=None)
@given(
    st.lists(star_polygons(), min_size=1, max_size=8),
    st.sampled_from([4, 32, 200]),
    st.floats(0, 1),
    st.floats(-1e6, 1e6),
)
def test_the_vectorised_first_pass_is_the_ops_pass(polys, budget, quantile, offset):
    """_first_heaps measures with np.hypot only to drop what is clearly too high or too far:
    its entries are the _ops pass's, to the last bit, with the tolerance at one of the
    ring's own operation heights (the edge of the pruning) and rings far from the origin."""
    from alphafence.geo.outward_many import _first_heaps

    rings = []
    for poly in polys:
        if poly.geom_type != "Polygon":
            continue
        pts = np.asarray(poly.exterior.coords)[:-1] + (offset, -offset)
        rings.append(pts if shapely.LinearRing(pts).is_ccw else pts[::-1].copy())
    heights = [op[1] for r in rings for op in _ops_pass(r, 0, math.inf)]
    tol = float(np.quantile(heights, quantile, method="nearest")) if heights else 1.0
    import alphafence.geo.outward_many as outward_module

    batch_min, outward_module.BATCH_MIN_VERTICES = outward_module.BATCH_MIN_VERTICES, 0
    try:
        heaps = _first_heaps(rings, budget, tol)
    finally:
        outward_module.BATCH_MIN_VERTICES = batch_min
    for ring, heap in zip(rings, heaps):
        assert sorted(heap, key=lambda op: op[2:4]) == _ops_pass(ring, budget, tol)


@st.composite
def rings(draw):
    """Rings on a coarse grid (repeated, closing and collinear vertices, no area), moved far
    away or shrunk to a hair, as LinearRings (or empty)."""
    pts = draw(st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), max_size=9))
    scale, offset = draw(st.sampled_from([1.0, 1e-9, 1e3])), draw(st.floats(-1e6, 1e6))
    if draw(st.booleans()) and pts:
        pts = pts + pts[:1]
    if len(pts) < 3:
        return shapely.LinearRing()
    return shapely.linearrings(np.asarray(pts, float) * scale + offset)


@settings(max_examples=100, deadline=None)
@given(st.lists(rings(), min_size=1, max_size=8))
def test_many_rings_are_cleaned_and_oriented_as_one_at_a_time(many):
    """rings_coords is ring_coords of each ring, and ring_signs the sign signed_area gives,
    however close to no area the ring is."""
    from alphafence.geo.rings import ring_coords, ring_signs, rings_coords, signed_area

    pts, counts, closed = rings_coords(np.asarray(many, dtype=object))
    assert [p.tolist() for p in pts] == [ring_coords(r).tolist() for r in many]
    assert counts.tolist() == [shapely.get_num_coordinates(r) for r in many]
    assert closed.tolist() == [len(p) > 1 and p[0].tolist() == p[-1].tolist() for p in pts]
    some = [p for p in pts if len(p)]
    if some:
        assert ring_signs(some).tolist() == [int(np.sign(signed_area(p))) for p in some]


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    vertices=st.sampled_from([4, 40, 999, 1000, 3000]),
    margin=st.floats(0.0, 60.0),
)
def test_clear_of_is_the_plain_distance(seed, vertices, margin):
    """Whether a fence's boundary keeps a margin from a geometry, as the plain distance says,
    for boundaries measured plainly and those indexed first (1,000 vertices or more)."""
    from alphafence.geo.rings import clear_of

    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, vertices, endpoint=False)
    radius = 100.0 + rng.uniform(0, 5, vertices)
    fence = shapely.Polygon(np.c_[radius * np.cos(t), radius * np.sin(t)])
    centres = rng.uniform(-90, 90, size=(6, 2))
    houses = shapely.buffer(shapely.points(centres), rng.uniform(1, 30, 6))
    boundaries = np.array([fence.boundary] * 6, dtype=object)
    want = shapely.distance(boundaries, houses) >= margin
    assert clear_of(boundaries, houses, margin).tolist() == want.tolist()
    assert clear_of(fence.boundary, houses[0], margin) == bool(want[0])


def test_a_clear_of_measuring_from_centres_is_caught(monkeypatch):
    """The broken case: distances taken between the geometries' centres call a house that
    touches the fence's line clear, and the comparison above sees it."""
    import types

    from alphafence.geo import rings

    fence = shapely.Point(0, 0).buffer(100.0, 16)
    house = shapely.Point(95, 0).buffer(10.0)
    assert not rings.clear_of(fence.boundary, house, 5.0)
    centres = lambda a, b: shapely.distance(shapely.centroid(a), shapely.centroid(b))  # noqa: E731
    broken = types.SimpleNamespace(**{**vars(shapely), "distance": centres})
    monkeypatch.setattr(rings, "shapely", broken)
    assert rings.clear_of(fence.boundary, house, 5.0)
