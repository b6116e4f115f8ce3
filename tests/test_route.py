"""Routing around keep-out fences: clearance and completeness properties on small random
scenes, checked independently (exact shapely distances, a fine grid search)."""

import math

import numpy as np
import pytest
import shapely
import shapely.affinity  # shapely 2.0 does not load it with shapely
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from alphafence.route import NoRoute, Roadmap

SIZE = 400.0  # scenes are SIZE x SIZE metres
GRID = 4.0  # reference grid resolution (m)
SLACK = 2 * GRID  # the grid must find the way with this much more clearance


@st.composite
def scenes(draw):
    n = draw(st.integers(1, 7))
    polys = []
    for _ in range(n):
        x = draw(st.floats(20, SIZE - 20))
        y = draw(st.floats(20, SIZE - 20))
        kind = draw(st.sampled_from(["rect", "disc", "bar"]))
        if kind == "disc":
            g = shapely.Point(x, y).buffer(draw(st.floats(8, 60)), quad_segs=6)
        else:
            w = draw(st.floats(10, 150))
            h = draw(st.floats(10, 150)) if kind == "rect" else draw(st.floats(4, 15))
            g = shapely.box(x - w / 2, y - h / 2, x + w / 2, y + h / 2)
            angle = draw(st.floats(0, 180))
            g = shapely.affinity.rotate(g, angle, origin=(x, y))
        polys.append(g)
    clearance = draw(st.sampled_from([3.0, 8.0, 15.0]))
    ends = draw(st.lists(st.tuples(st.floats(0, SIZE), st.floats(0, SIZE)), min_size=2, max_size=2))
    return polys, clearance, np.array(ends, float)


def exact_clearance(xy, polys):
    legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    return float(shapely.distance(legs, shapely.union_all(polys)).min())


def grid_connected(polys, clearance, s, g):
    """8-connected grid search: is there a chain of grid cells clear by ``clearance`` from
    the cell next to ``s`` to the cell next to ``g``? (None if s or g cannot join the grid)."""
    union = shapely.union_all(polys)
    ticks = np.arange(-2 * GRID, SIZE + 2 * GRID + 1e-9, GRID)
    X, Y = np.meshgrid(ticks, ticks, indexing="ij")
    d = shapely.distance(shapely.points(X.ravel(), Y.ravel()), union).reshape(X.shape)
    free = d >= clearance
    labels, _ = ndimage.label(free, structure=np.ones((3, 3)))

    def join(p):
        i, j = int(round((p[0] - ticks[0]) / GRID)), int(round((p[1] - ticks[0]) / GRID))
        if not free[i, j]:
            return None
        node = (ticks[i], ticks[j])
        seg = shapely.Point(p) if np.allclose(p, node) else shapely.LineString([p, node])
        return labels[i, j] if shapely.distance(seg, union) >= clearance else None

    a, b = join(s), join(g)
    if a is None or b is None:
        return None
    return a == b


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_every_route_keeps_the_clearance(scene):
    polys, clearance, (s, g) = scene
    rm = Roadmap(polys, clearance=clearance, bounds=(0, 0, SIZE, SIZE))
    try:
        r = rm.route(s, g)
    except NoRoute:
        return
    assert np.allclose(r.xy[0], s) and np.allclose(r.xy[-1], g)
    assert exact_clearance(r.xy, polys) >= clearance
    assert r.length_m >= math.hypot(*(g - s)) - 1e-6


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_a_route_is_found_whenever_a_fine_grid_finds_one(scene):
    polys, clearance, (s, g) = scene
    connected = grid_connected(polys, clearance + SLACK, s, g)
    assume(connected is not None)
    rm = Roadmap(polys, clearance=clearance, bounds=(0, 0, SIZE, SIZE))
    if connected:
        r = rm.route(s, g)  # raises NoRoute if the roadmap misses the way
        assert exact_clearance(r.xy, polys) >= clearance


def test_route_is_short_around_a_wall():
    wall = shapely.box(190, 50, 210, 350)
    rm = Roadmap([wall], clearance=10.0)
    r = rm.route((100, 200), (300, 200))
    assert exact_clearance(r.xy, [wall]) >= 10.0
    # shortest: over a corner of the wall buffered by 10 m (a tangent path via (200, 360))
    best = 2 * math.hypot(100, 160) + 0.0
    assert r.length_m <= 1.05 * best


def test_roadmap_is_reusable_and_queries_are_independent():
    polys = [shapely.box(100, 0, 120, 300), shapely.box(250, 100, 270, 400)]
    rm = Roadmap(polys, clearance=5.0, bounds=(0, 0, 400, 400))
    a = rm.route((50, 50), (350, 350))
    rm.route((350, 50), (50, 350))
    b = rm.route((50, 50), (350, 350))
    assert np.array_equal(a.xy, b.xy)
    back = rm.route((350, 350), (50, 50))
    assert back.length_m == pytest.approx(a.length_m, rel=0.05)


def test_straight_line_when_nothing_is_in_the_way():
    rm = Roadmap([shapely.box(0, 0, 10, 10)], clearance=5.0)
    r = rm.route((100, 0), (100, 100))
    assert len(r.xy) == 2 and r.length_m == pytest.approx(100.0)


def test_warning_layers_cost_more_than_open_air():
    # the way north of the fence is shorter but crosses a warning layer; south is open air
    keep_out = [shapely.box(170, -80, 230, 20)]
    warning = [shapely.box(150, 0, 250, 200)]
    rm = Roadmap(keep_out, warning, clearance=5.0, bounds=(0, -200, 400, 200))
    r = rm.route((100, 0), (300, 0))
    assert r.warning_m < 1e-6 and r.xy[:, 1].min() < -80
    assert exact_clearance(r.xy, keep_out) >= 5.0
    # without the warning layer the shorter way north is taken
    r2 = Roadmap(keep_out, clearance=5.0, bounds=(0, -200, 400, 200)).route((100, 0), (300, 0))
    assert r2.xy[:, 1].max() > 20 and r2.length_m < r.length_m


def test_start_inside_a_fence_is_named():
    rm = Roadmap([shapely.box(0, 0, 50, 50)], clearance=5.0, names=["prison/1"])
    with pytest.raises(NoRoute, match="start is inside keep-out fence prison/1"):
        rm.route((25, 25), (200, 200))


def test_goal_too_close_to_a_fence_is_named():
    rm = Roadmap([shapely.box(0, 0, 50, 50)], clearance=10.0, names=["prison/1"])
    with pytest.raises(NoRoute, match=r"goal is 3\.0 m from keep-out fence prison/1"):
        rm.route((200, 200), (53, 25))


def test_enclosed_goal_names_the_enclosing_fences():
    ring = [
        shapely.box(0, 0, 200, 20),
        shapely.box(0, 180, 200, 200),
        shapely.box(0, 0, 20, 200),
        shapely.box(180, 0, 200, 175),  # a 5 m gap: narrower than twice the clearance
        shapely.box(500, 500, 510, 510),
    ]
    names = ["south", "north", "west", "east", "far"]
    rm = Roadmap(ring, clearance=10.0, names=names)
    with pytest.raises(NoRoute) as err:
        rm.route((-100, 100), (100, 100))
    msg = str(err.value)
    assert "goal is enclosed by keep-out fences" in msg
    assert all(n in msg for n in ("south", "north", "west", "east")) and "far" not in msg
    # with a small enough clearance the gap is passable
    r = Roadmap(ring, clearance=2.0, names=names).route((-100, 100), (100, 100))
    assert exact_clearance(r.xy, ring) >= 2.0
