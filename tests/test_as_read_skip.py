"""The build holds a fence as read only where it can matter (alphafence.fencing.as_read): a
fence whose every edge is short enough not to bow (alphafence.geo.lonlat.bow_free, edge by
edge), or whose edges keep from the zone its margin plus the most each can bow
(clear_as_read), is written as it was made. Property: every fence so skipped holds as
ArduPilot reads it (tests/ardupilot_model.py: integer lon/lat vertices, straight lon/lat
edges, geodesic distances). Broken on purpose: the same skip without the bow, or measured
on a fence's longest edge at the equator's latitude, accepts fences that do not hold."""

from __future__ import annotations

import math

import numpy as np
import shapely
import shapely.affinity
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.fencing import as_read
from alphafence.fencing.as_read import clear_as_read
from alphafence.geo.frame import LocalFrame
from alphafence.geo.lonlat import bow_free

from .ardupilot_model import covers_as_read, excursion_m


def fence_and_zone(lat, length_m, width_m, margin_m, gap_m, turn):
    """A strip zone ``length_m`` long and a fence around it ``gap_m`` beyond the margin on
    its long sides (edges as long as the zone), turned by ``turn`` degrees, in a frame at
    ``lat``: the fence in metres, the zone in metres and lon/lat, the frame."""
    frame = LocalFrame(10.0, lat)
    zone = shapely.box(-length_m / 2, -width_m / 2, length_m / 2, width_m / 2)
    out = margin_m + gap_m
    fence = shapely.box(-length_m / 2 - out, -width_m / 2 - out,
                        length_m / 2 + out, width_m / 2 + out)  # fmt: skip
    zone, fence = (shapely.affinity.rotate(g, turn, origin=(0, 0)) for g in (zone, fence))
    return fence, zone, frame


def holds_as_read(fence, zone_local, frame, margin_m) -> bool:
    """The fence's vertices as written (lon/lat), read as ArduPilot reads them, contain the
    zone (its lon/lat reading of the same metric outline, densified) plus the margin."""
    ring = np.column_stack(frame.to_wgs84(*np.asarray(fence.exterior.coords).T))
    zone = shapely.segmentize(zone_local, 50.0)
    zone = shapely.Polygon(np.column_stack(frame.to_wgs84(*np.asarray(zone.exterior.coords).T)))
    return covers_as_read([ring], zone) and excursion_m(zone, [ring], margin_m) <= 0.0


strip = dict(
    lat=st.floats(-75, 75),
    length_m=st.floats(300, 40_000),
    width_m=st.floats(10, 2_000),
    margin_m=st.floats(5, 200),
    gap_m=st.floats(0.0, 3.0),
    turn=st.sampled_from([0.0, 15.0, 45.0, 90.0]),
)


@settings(max_examples=120, deadline=None)
@given(**strip)
def test_a_fence_skipped_as_clear_holds_as_read(lat, length_m, width_m, margin_m, gap_m, turn):
    fence, zone, frame = fence_and_zone(lat, length_m, width_m, margin_m, gap_m, turn)
    if clear_as_read(fence, frame, zone, margin_m) or bow_free([fence], frame)[0]:
        assert holds_as_read(fence, zone, frame, margin_m - as_read.READ_SLACK_M)


def test_the_skip_takes_the_short_edged_fences_of_a_long_site():
    # 3 km long but its edges 300 m: no edge can bow a centimetre at 36 N
    frame = LocalFrame(14.5, 35.9)
    bottom = [(x, 0.0) for x in range(0, 3001, 300)]
    top = [(x, 300.0) for x in range(3000, -1, -300)]
    assert bow_free([shapely.Polygon(bottom + top)], frame)[0]
    assert not bow_free([shapely.box(0, 0, 3000, 300)], frame)[0]


def test_without_the_bow_the_skip_accepts_fences_that_do_not_hold(monkeypatch):
    # broken on purpose: edges of 40 km at 70 N keep just the margin in metres; their lon/lat
    # reading bows tens of metres, into the margin on one side
    fence, zone, frame = fence_and_zone(70.0, 40_000.0, 200.0, 50.0, 0.1, 0.0)
    assert not clear_as_read(fence, frame, zone, 50.0)
    assert not holds_as_read(fence, zone, frame, 50.0 - as_read.READ_SLACK_M)
    monkeypatch.setattr(as_read, "EARTH_RADIUS_M", math.inf)  # the bow term: zero
    assert clear_as_read(fence, frame, zone, 50.0)


def test_edges_read_at_the_equators_latitude_are_short_of_their_bow(monkeypatch):
    # broken on purpose: 3 km edges at 70 N bow half a metre as read; the bound taken at
    # latitude 0 says 18 cm, within the fence's 30 cm to spare, and passes it
    fence, zone, frame = fence_and_zone(70.0, 3_000.0, 200.0, 50.0, 0.3, 0.0)
    assert not clear_as_read(fence, frame, zone, 50.0)
    assert not holds_as_read(fence, zone, frame, 50.0 - as_read.READ_SLACK_M)
    monkeypatch.setattr(frame, "lat0", 0.0)
    assert clear_as_read(fence, frame, zone, 50.0)
