"""The fence set's per-position check (a grid of candidates, the STRtree outside it) answers
exactly what a plain loop over every fence answers: the fences a position is inside (within
their bands and in force), the keep-ins it has left, the nearest keep-out (at any altitude and
within the vertical reach) with its distance, and the first keep-out along the track.
Property-tested over random fence sets (boxes, circles, irregular polygons, polygons with a
hole, multipolygons; keep-out, warning,
keep-in; altitude bands; a time window on or off) and random positions, on fences' vertices
and outside every fence's envelope too."""

import math
from datetime import datetime, timezone

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from alphafence.awareness.fenceset import KEEP_IN, KEEP_OUT, WARNING, Check, FenceSet, Hit
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame

FRAME = LocalFrame(14.5, 35.9)
WINDOW = {"startDateTime": "2026-01-01T10:00:00Z", "endDateTime": "2026-01-01T11:00:00Z"}

xy = st.floats(-2000, 2000)
shape = st.one_of(
    st.tuples(st.just("box"), xy, xy, st.floats(5, 800), st.floats(5, 800)),
    st.tuples(st.just("circle"), xy, xy, st.floats(5, 400)),
    st.tuples(st.just("poly"), st.lists(st.tuples(xy, xy), min_size=3, max_size=9)),
    st.tuples(st.just("donut"), xy, xy, st.floats(20, 800)),  # a hole: its ring is an edge
    st.tuples(st.just("two"), xy, xy, st.floats(5, 300)),  # a multipolygon
)
fence = st.tuples(
    st.sampled_from(["keep_out", "keep_out", "keep_out", "warning", "keep_in"]),
    shape,
    st.one_of(st.none(), st.tuples(st.floats(0, 60), st.floats(61, 200))),
    st.booleans(),  # a time window
)


def geometry(spec):
    if spec[0] == "box":
        _, x, y, w, h = spec
        return shapely.box(x, y, x + w, y + h)
    if spec[0] == "circle":
        _, x, y, r = spec
        return shapely.Point(x, y).buffer(r, quad_segs=8)
    if spec[0] == "donut":
        _, x, y, w = spec
        return shapely.box(x, y, x + w, y + w).difference(
            shapely.box(x + w / 4, y + w / 4, x + 3 * w / 4, y + 3 * w / 4)
        )
    if spec[0] == "two":
        _, x, y, w = spec
        return shapely.MultiPolygon(
            [shapely.box(x, y, x + w, y + w), shapely.box(x + 2 * w, y, x + 3 * w, y + w)]
        )
    hull = shapely.MultiPoint(spec[1]).convex_hull
    return hull if hull.geom_type == "Polygon" and hull.area > 1.0 else shapely.box(0, 0, 10, 10)


def fence_set(specs):
    records = []
    for i, (kind, spec, band, timed) in enumerate(specs):
        lo, hi = band if band else (None, None)
        props = {"zone": {"applicability": [WINDOW]}} if timed else None
        geom = FRAME.geom_to_wgs84(geometry(spec))
        records.append(FenceRecord(f"f/{i}", kind, geom, 0.0, lo, hi, properties=props))
    return FenceSet(records, FRAME)


def plain_check(fs, x, y, alt, vx, vy, lookahead_m, vertical_m):
    """Every fence asked in turn, the lowest index first among equals."""
    p, n = shapely.Point(x, y), len(fs.records)
    in_force = [bool(fs.active[k]) for k in range(n)]
    in_band = [bool(fs.alt_min[k] <= alt <= fs.alt_max[k]) and in_force[k] for k in range(n)]
    reach = [
        bool(fs.alt_min[k] - vertical_m <= alt <= fs.alt_max[k] + vertical_m) and in_force[k]
        for k in range(n)
    ]
    inside = [k for k in range(n) if in_band[k] and fs.local[k].intersects(p)]
    inside_out = [k for k in inside if fs.kind[k] == KEEP_OUT]
    inside_warn = [k for k in inside if fs.kind[k] == WARNING]
    keep_ins = [k for k in range(n) if fs.kind[k] == KEEP_IN and in_force[k]]
    # the kit's keep-in fences are areas to fly in: inside any one is inside
    outside_in = [] if any(k in inside for k in keep_ins) else keep_ins
    keep_outs = [k for k in range(n) if fs.kind[k] == KEEP_OUT and in_force[k]]
    dist = {k: float(shapely.distance(p, fs.local[k])) for k in keep_outs}
    nearest = min(((dist[k], k) for k in keep_outs), default=None)
    any_m = math.inf if nearest is None else nearest[0]
    if not math.isinf(vertical_m) and nearest is not None and not reach[nearest[1]]:
        nearest = min(((dist[k], k) for k in keep_outs if reach[k]), default=None)
    ahead, speed = None, math.hypot(vx, vy)
    if nearest is not None and 0 < nearest[0] <= lookahead_m and speed > 0.05:
        ux, uy = vx / speed, vy / speed
        ray = shapely.LineString([(x, y), (x + ux * lookahead_m, y + uy * lookahead_m)])
        hits = []
        for k in keep_outs:
            if k in inside_out or (not math.isinf(vertical_m) and not reach[k]):
                continue
            if ray.intersects(fs.local[k]):
                along = float(shapely.distance(p, shapely.intersection(ray, fs.local[k])))
                if not math.isnan(along):
                    hits.append((along, k))
        ahead = (min(hits)[1], min(hits)[0]) if hits else None
    hit = None if nearest is None else Hit(nearest[1], nearest[0], nearest[0] == 0.0)
    return Check(inside_out, inside_warn, outside_in, hit, ahead, any_m)


@settings(max_examples=150, deadline=None)
@given(
    specs=st.lists(fence, min_size=1, max_size=12),
    points=st.lists(st.tuples(st.floats(-3000, 3000), st.floats(-3000, 3000)), max_size=8),
    on_vertex=st.integers(0, 10_000),
    alt=st.floats(-20, 250),
    heading=st.floats(-math.pi, math.pi),
    speed=st.sampled_from([0.0, 3.0, 12.0]),
    lookahead=st.floats(0, 1500),
    vertical=st.sampled_from([math.inf, 10.0, 40.0]),
    window_open=st.booleans(),
)
def test_the_check_answers_as_a_plain_loop_over_every_fence(
    specs, points, on_vertex, alt, heading, speed, lookahead, vertical, window_open
):
    fs = fence_set(specs)
    fs.set_time(datetime(2026, 1, 1, 10 if window_open else 9, 30, tzinfo=timezone.utc))
    corners = shapely.get_coordinates(fs.local)
    vertex = corners[on_vertex % len(corners)]
    x0, y0, x1, y1 = shapely.total_bounds(fs.local)
    tests = [*points, tuple(vertex), (x1 + 500.0, y1 + 1.0), ((x0 + x1) / 2, (y0 + y1) / 2)]
    vx, vy = speed * math.sin(heading), speed * math.cos(heading)
    for x, y in tests:
        args = (float(x), float(y), alt, vx, vy, lookahead, vertical)
        assert_same(fs, fs.check(*args), plain_check(fs, *args), args)


ALONG_M = 1e-6  # the track's first fence is solved from its edges: GEOS's answer to rounding


def assert_same(fs, got, want, args):
    """Equal checks but for the first fence ahead, which is solved from the fences' edges: it
    is never missed nor later than GEOS's (beyond :data:`ALONG_M`), and where it is said to be
    met, the track is within :data:`ALONG_M` of it (a fence the track runs along or grazes
    within rounding may be met sooner than GEOS's exact arithmetic says: the safe side)."""
    assert (got.inside_keep_out, got.inside_warning, got.outside_keep_in) == (
        want.inside_keep_out,
        want.inside_warning,
        want.outside_keep_in,
    ), args
    assert (got.nearest_keep_out, got.keep_out_any_m) == (
        want.nearest_keep_out,
        want.keep_out_any_m,
    ), args
    if got.breach_ahead == want.breach_ahead:
        return
    assert got.breach_ahead is not None, ("a fence ahead missed", args, want)
    x, y, _, vx, vy, _, _ = args
    (k, d), speed = got.breach_ahead, math.hypot(vx, vy)
    met = shapely.Point(x + vx / speed * d, y + vy / speed * d)
    assert shapely.distance(met, fs.local[k]) <= ALONG_M, ("not met there", args, got, want)
    if want.breach_ahead is not None:
        assert d <= want.breach_ahead[1] + ALONG_M, ("met later", args, got, want)


def test_overlapping_keep_outs_name_the_lowest_index_nearest():
    # a position inside two keep-outs is at 0 m from both: the first one is the nearest
    square = FRAME.geom_to_wgs84(shapely.box(0, 0, 100, 100))
    fs = FenceSet([FenceRecord(f"k/{i}", "keep_out", square) for i in range(3)], FRAME)
    check = fs.check(50.0, 50.0)
    assert check.inside_keep_out == [0, 1, 2]
    assert check.nearest_keep_out == Hit(0, 0.0, True)
    assert fs.check(150.0, 50.0, 0.0, -10.0, 0.0, 200.0).breach_ahead == (
        0,
        pytest.approx(50.0, abs=1e-6),
    )


def test_positions_beyond_the_fences_are_answered_too():
    # far outside the fences' envelope (no grid cell), the nearest keep-out is still found
    rings = [shapely.box(x, 0, x + 10, 10) for x in np.arange(0.0, 500.0, 50.0)]
    fs = FenceSet(
        [FenceRecord(f"k/{i}", "keep_out", FRAME.geom_to_wgs84(g)) for i, g in enumerate(rings)],
        FRAME,
    )
    for x, y in [(-5000.0, 3.0), (8000.0, -40.0), (250.0, 9000.0)]:
        assert fs.check(x, y) == plain_check(fs, x, y, 0.0, 0.0, 0.0, 0.0, math.inf)


@settings(max_examples=200, deadline=None)
@given(
    specs=st.lists(fence, min_size=1, max_size=6),
    start=st.tuples(st.floats(-3000, 3000), st.floats(-3000, 3000)),
    heading=st.floats(-math.pi, math.pi),
    length=st.floats(0.1, 3000),
    aim=st.one_of(st.none(), st.integers(0, 10**6)),
)
def test_a_few_segments_in_plain_floats_meet_the_track_where_numpy_does(
    specs, start, heading, length, aim
):
    """The first fence ahead is solved one segment at a time for a few segments and in numpy
    for many: the same arithmetic, the same metres to the last bit; and leaving out the
    segments whose boxes miss the track's (widened by the most slack) changes nothing, also
    for a track that ends on a fence's vertex (``aim``: which one) or grazes it."""
    from alphafence.awareness.rays import FenceEdges

    local = np.array([geometry(spec) for _, spec, _, _ in specs], dtype=object)
    edges = FenceEdges(local)
    if aim is not None:  # end the track on a vertex
        vx, vy = shapely.get_coordinates(local)[aim % len(shapely.get_coordinates(local))]
        heading, length = (
            math.atan2(vx - start[0], vy - start[1]),
            math.hypot(vx - start[0], vy - start[1]),
        )
        assume(length > 0.0)
    ux, uy = math.sin(heading), math.cos(heading)
    box = edges.track_box(*start, ux, uy, length)
    for k in range(len(local)):
        a, b = int(edges.indptr[k]), int(edges.indptr[k + 1])
        few = edges._along_few(*start, ux, uy, length, a, b)
        many = edges._along(*start, ux, uy, length, np.arange(a, b))
        assert few == (float(many.min()) if many.size else math.inf), (k, start, heading)
        assert edges._along_few(*start, ux, uy, length, a, b, box) == few, (k, start, heading)


def test_a_track_along_a_fences_edge_meets_it_where_the_edge_begins():
    """A heading of 1e-38 rad is parallel to a north-south edge for every purpose: the track
    meets the fence at the edge's near end (1.9 m), not at its start (found by the qemu run's
    hypothesis, where the nearly parallel lines were solved as crossing)."""
    square = FRAME.geom_to_wgs84(shapely.box(0, 0, 800, 679.1))
    fs = FenceSet([FenceRecord("k/0", "keep_out", square)], FRAME)
    heading = 1.1754943508222875e-38
    check = fs.check(0.0, -1.9, 0.0, 12 * math.sin(heading), 12 * math.cos(heading), 1500.0)
    assert check.breach_ahead == (0, pytest.approx(1.9, abs=1e-6))
