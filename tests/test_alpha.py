"""Alpha shapes: automatic alpha is the smallest radius joining a site into one piece."""

import math

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.geo.alpha import alpha_shape


def squares(centres, size=10.0):
    return shapely.union_all([shapely.box(x, y, x + size, y + size) for x, y in centres])


def test_single_part_site_is_its_own_shape():
    region = shapely.Polygon(
        [(0, 0), (100, 0), (100, 100), (60, 100), (60, 30), (40, 30), (40, 100), (0, 100)]
    )
    shape, alpha = alpha_shape(region)
    assert alpha == 0.0 and shape.equals(region)  # the U keeps its notch


def test_l_shaped_campus_is_joined_tighter_than_its_hull():
    region = squares([(0, 0), (20, 0), (40, 0), (0, 20), (0, 40)])  # 10 m gaps, an L
    shape, alpha = alpha_shape(region)
    assert shape.geom_type == "Polygon" and shape.covers(region)
    assert 5 < alpha < 30
    hull = region.convex_hull
    assert shape.area < 0.8 * hull.area  # the inside corner of the L stays open


def test_forced_small_alpha_leaves_parts_apart_and_large_alpha_is_the_hull():
    region = squares([(0, 0), (100, 0)])
    apart, _ = alpha_shape(region, alpha=5.0)
    assert apart.geom_type == "MultiPolygon" and len(apart.geoms) == 2 and apart.covers(region)
    joined, _ = alpha_shape(region, alpha=1e6)
    assert joined.geom_type == "Polygon" and math.isclose(
        joined.area, region.convex_hull.area, rel_tol=1e-9
    )


def test_collinear_parts_fall_back_safely():
    region = shapely.union_all(
        [shapely.Point(0, 0).buffer(1, quad_segs=1), shapely.Point(50, 0).buffer(1, quad_segs=1)]
    )
    shape, _ = alpha_shape(region)
    assert shape.covers(region) and shape.geom_type == "Polygon"


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0, 300), st.floats(0, 300)), min_size=2, max_size=7, unique=True)
)
def test_auto_alpha_is_the_smallest_radius_giving_one_piece(centres):
    region = squares(centres, 8.0)
    if region.geom_type == "Polygon":
        return
    shape, alpha = alpha_shape(region)
    assert shape.geom_type == "Polygon" and shape.covers(region)
    # a slightly smaller alpha must leave the site in pieces
    below, _ = alpha_shape(region, alpha=alpha * (1 - 1e-6))
    assert below.geom_type == "MultiPolygon"


def test_plain_alpha_shape_matches_the_alphashape_package():
    alphashape = __import__("pytest").importorskip("alphashape")
    from alphafence.geo.alpha import alpha_shape_points

    rng = np.random.default_rng(7)
    pts = np.concatenate([rng.uniform(0, 100, (150, 2)), rng.uniform(200, 260, (80, 2))])
    # (at small radii alphashape also fills holes and faces between pinched parts,
    # which is not the alpha shape; compare where the shape has neither)
    for radius in (15.0, 40.0):
        ours = alpha_shape_points(pts, radius)
        theirs = alphashape.alphashape([tuple(p) for p in pts], 1.0 / radius)
        assert math.isclose(ours.area, theirs.area, rel_tol=1e-6)
        assert ours.symmetric_difference(theirs).area < 1e-6 * ours.area
