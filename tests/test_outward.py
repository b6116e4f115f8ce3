"""Conservative simplification: outward only adds area, inward only removes it."""

import math

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.geo.outward import simplify_polygon, simplify_ring


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
