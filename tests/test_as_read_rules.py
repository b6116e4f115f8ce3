"""The as-read checks the build leans on (``alphafence.fencing.as_read``), held to their rules
as the module states them, on fences a few centimetres either side of the line:

- ``clear_as_read``: the fence covers the zone and every edge keeps from it the margin, the
  readings' tolerances (6 cm) and the most its lon/lat reading can bow
  (``L^2 (tan|lat| + 1) / 8R`` at the fence's farthest latitude);
- ``reads_covering``: the fence's lon/lat reading covers the zone with the margin and 6 cm;
- ``readable``: every ring's lon/lat reading spans under 180 degrees of longitude and is a
  valid ring."""

from __future__ import annotations

import math

import numpy as np
import pyproj
import shapely
import shapely.affinity
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.fencing.as_read import clear_as_read, readable, reads_covering
from alphafence.geo.frame import LocalFrame

SLACK = 0.06  # the zone's densified edges (5 cm) and the check's own reading (1 cm)
R = 6_371_008.8


def spec_clear(local, lat0, zone, margin):
    if not shapely.covers(local, zone):
        return False
    worst = []
    for ring in shapely.get_rings(shapely.get_parts(local)):
        c = np.asarray(ring.coords)
        worst.append(c)
    reach = max(float(np.abs(c).max()) for c in worst)
    lat = min(abs(lat0) + reach / 111_319.49, 89.0)
    for c in worst:
        for a, b in zip(c[:-1], c[1:]):
            bow = math.dist(a, b) ** 2 * (math.tan(math.radians(lat)) + 1.0) / (8 * R)
            if shapely.LineString([a, b]).distance(zone) < margin + SLACK + bow:
                return False
    return True


@settings(max_examples=80, deadline=None)
@given(
    lat=st.floats(-80.0, 80.0),
    dx=st.floats(-300_000.0, 300_000.0),
    dy=st.floats(-300_000.0, 300_000.0),
    size=st.floats(20.0, 20_000.0),
    margin=st.sampled_from([0.0, 10.0, 100.0]),
    gap=st.sampled_from([-0.5, 0.01, 0.03, 0.2, 1.0, 30.0]),
    turn=st.floats(0.0, 90.0),
)
def test_clear_as_read_is_its_rule(lat, dx, dy, size, margin, gap, turn):
    frame = LocalFrame(14.5, lat)
    zone = shapely.affinity.rotate(shapely.box(0, 0, size, size / 3), turn, origin=(0, 0))
    zone = shapely.affinity.translate(zone, dx, dy)
    fence = zone.buffer(margin + gap, join_style="mitre")
    assert clear_as_read(fence, frame, zone, margin) == spec_clear(fence, lat, zone, margin)


def test_clear_as_read_at_the_line():
    frame = LocalFrame(14.5, 35.9)
    zone = shapely.box(0, 0, 200, 100)  # edges of 200 m: bows under a millimetre
    for margin in (0.0, 25.0):
        assert clear_as_read(zone.buffer(margin + 0.08, join_style="mitre"), frame, zone, margin)
        assert not clear_as_read(
            zone.buffer(margin + 0.01, join_style="mitre"), frame, zone, margin
        )
        assert not clear_as_read(shapely.box(10, 0, 200, 100), frame, zone, margin)  # uncovered
    # far from the frame's origin the bow is bounded at the latitude the fence reaches
    far = shapely.box(0, 2_000_000, 20_000, 2_000_100)
    fence = far.buffer(2.0, join_style="mitre")  # 20 km edges at 54 degrees bow 13 m
    assert not clear_as_read(fence, frame, far, 0.0)
    assert clear_as_read(far.buffer(40.0, join_style="mitre"), frame, far, 0.0)


def test_reads_covering_at_the_line():
    for lat in (0.0, 35.9, -64.0):
        frame = LocalFrame(14.5, lat)
        zone = shapely.box(0, 0, 200, 100)
        for margin in (0.0, 25.0):
            assert reads_covering(
                zone.buffer(margin + 0.2, join_style="mitre"), frame, zone, margin
            )
            assert not reads_covering(
                zone.buffer(margin + 0.02, join_style="mitre"), frame, zone, margin
            )
            assert not reads_covering(shapely.box(5, 0, 200, 100), frame, zone, margin)
        # a long edge whose bow brings its reading into the margin: the metric fence holds,
        # the reading does not
        long_zone = shapely.box(-30_000, 0, 30_000, 100)
        fence = long_zone.buffer(1.0, join_style="mitre")
        bows = lat != 0.0
        assert reads_covering(fence, frame, long_zone, 0.0) is not bows


def test_readable_is_its_rule():
    frame = LocalFrame(0.0, -44.0)
    box = shapely.box(0, 0, 50_000, 50_000)
    holed = shapely.Polygon(
        box.exterior.coords, [shapely.box(10, 10, 40_000, 40_000).exterior.coords]
    )
    assert readable(box, frame) and readable(holed, frame)
    assert readable(shapely.MultiPolygon([box, shapely.box(60_000, 0, 70_000, 10_000)]), frame)
    assert not readable(shapely.Polygon([(-1.2e7, 0), (1.2e7, 0), (0, 1e5)]), frame)
    # a ring valid in metres whose lon/lat reading crosses itself: near the pole, a thin
    # wedge whose two long sides swap sides when read as straight lon/lat lines
    polar = LocalFrame(0.0, 88.0)
    aeqd = pyproj.Transformer.from_crs(
        "EPSG:4326", "+proj=aeqd +lat_0=88 +lon_0=0 +ellps=WGS84", always_xy=True
    )
    pts = [aeqd.transform(lon, lat) for lon, lat in ((-170, 87.0), (170, 87.0), (0, 89.5))]
    wedge = shapely.Polygon(pts)
    assert wedge.is_valid
    lon = np.array([-170.0, 170.0, 0.0])
    unwrapped = np.unwrap(np.radians(lon))
    spans = np.ptp(np.degrees(unwrapped)) >= 180.0
    assert readable(wedge, polar) is (not spans and shapely.LinearRing(
        np.column_stack([np.degrees(unwrapped), [87.0, 87.0, 89.5]])).is_valid)  # fmt: skip
    # in the hole: the second ring is read too
    bad_hole = shapely.Polygon(box.exterior.coords, [[(-1.2e7, 0), (1.2e7, 0), (0, 1e5)]])
    assert not readable(bad_hole, frame)


def test_clear_as_read_bounds_the_bow_at_the_farthest_latitude_and_within_rings():
    frame = LocalFrame(14.5, 35.9)
    # 20 km edges 2,000 km north of the frame's origin (54 degrees): they may bow 18.6 m
    # there (13.5 m at the origin's latitude, 16.5 m with 9R for 8R)
    far = shapely.box(0, 2_000_000, 20_000, 2_000_100)
    assert not clear_as_read(far.buffer(17.5, join_style="mitre"), frame, far, 0.0)
    assert clear_as_read(far.buffer(19.0, join_style="mitre"), frame, far, 0.0)
    # a fence of two parts: the step from one ring to the next crosses the zone, and is
    # no edge
    zone = shapely.box(0, 0, 200, 100)
    ring = [(230, 130), (-30, 130), (-30, -30), (230, -30), (230, 130)]
    other = [(-900, -1000), (-900, -900), (-1000, -900), (-1000, -1000), (-900, -1000)]
    fence = shapely.MultiPolygon([shapely.Polygon(ring), shapely.Polygon(other)])
    assert clear_as_read(fence, frame, zone, 0.0)


def test_readable_refuses_a_crossed_ring_and_one_over_half_the_world():
    frame = LocalFrame(0.0, 0.0)
    bowtie = shapely.Polygon([(0, 0), (100, 100), (100, 0), (0, 100)])
    assert not readable(bowtie, frame)
    wide = [(-90.25, 10.0), (90.25, 10.0), (0.0, 20.0)]  # 180.5 degrees of longitude
    x, y = frame.to_local(np.array([p[0] for p in wide]), np.array([p[1] for p in wide]))
    assert not readable(shapely.Polygon(np.column_stack([x, y])), frame)
    narrow = [(-89.75, 10.0), (89.75, 10.0), (0.0, 20.0)]  # 179.5 degrees
    x, y = frame.to_local(np.array([p[0] for p in narrow]), np.array([p[1] for p in narrow]))
    assert readable(shapely.Polygon(np.column_stack([x, y])), frame)


def test_clear_as_read_checks_every_part_and_readable_every_half_world():
    frame = LocalFrame(14.5, 35.9)
    a, b = shapely.box(0, 0, 200, 100), shapely.box(5000, 0, 5200, 100)
    zone = shapely.MultiPolygon([a, b])
    fence = shapely.MultiPolygon(
        [a.buffer(30, join_style="mitre"), b.buffer(0.01, join_style="mitre")]
    )
    assert not clear_as_read(fence, frame, zone, 0.0)  # the second part is 1 cm off
    # a ring spanning 180.5 degrees of longitude in short steps is not readable; 179.5 is
    wide = LocalFrame(90.0, 5.0)
    for span, ok in ((180.5, False), (179.5, True)):
        lons = np.array([0.0, 60.0, 120.0, span, 120.0, 60.0]) - 90.0
        lats = np.array([0.0, 0.0, 0.0, 0.0, 10.0, 10.0])
        x, y = wide.to_local((lons + 180.0) % 360.0 - 180.0, lats)
        assert readable(shapely.Polygon(np.column_stack([x, y])), wide) is ok, span
