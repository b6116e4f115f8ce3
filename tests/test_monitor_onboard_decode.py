"""A vehicle's fence items back into geometry (alphafence.onboard.decode) for the monitor's
onboard layer: polygons as consecutive vertices with the same count, circles with their
radius (drawn to the safe side: an exclusion's polygon contains the circle, an inclusion's
lies within it), the return point ignored, each fence named after its items; malformed lists
refused in one line naming the item, whatever they hold."""

from __future__ import annotations

import math
import os
from types import SimpleNamespace

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
    fence_items,
)
from alphafence.onboard.decode import decode_fence

from .ardupilot_model import GEOD, LATLON_TO_M, location_distance_m

N = int(os.environ.get("ALPHAFENCE_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=N, deadline=None, suppress_health_check=list(HealthCheck))
FRAME = LocalFrame(14.5, 35.9)


def polygon(command, xy):
    lonlat = [FRAME.to_wgs84(x, y) for x, y in xy]
    return [FenceItem(command, float(len(xy)), float(lon), float(lat)) for lon, lat in lonlat]


def circle(command, x, y, r):
    lon, lat = FRAME.to_wgs84(x, y)
    return FenceItem(command, r, float(lon), float(lat))


def test_items_become_named_polygons_and_circles():
    items = [
        circle(RETURN_POINT, 0, 0, 0.0),
        *polygon(POLYGON_EXCLUSION, [(0, 100), (50, 100), (50, 150), (0, 150)]),
        circle(CIRCLE_EXCLUSION, 300, 0, 40.0),
        *polygon(POLYGON_INCLUSION, [(-1000, -1000), (1000, -1000), (0, 1000)]),
        *polygon(POLYGON_EXCLUSION, [(-200, 0), (-150, 0), (-150, 60)]),
        circle(CIRCLE_EXCLUSION, 0, -300, 25.0),
        circle(CIRCLE_INCLUSION, 0, 0, 2000.0),
    ]
    fences = decode_fence(items)
    assert [f.name for f in fences] == [
        "onboard exclusion polygon 1 (items 1-4)",
        "onboard exclusion circle 1 (item 5)",
        "onboard inclusion polygon 1 (items 6-8)",
        "onboard exclusion polygon 2 (items 9-11)",
        "onboard exclusion circle 2 (item 12)",
        "onboard inclusion circle 1 (item 13)",
    ]
    assert [f.short_name for f in fences][:2] == ["excl poly 1 #1-4", "excl circle 1 #5"]
    square = FRAME.geom_to_local(fences[0].geometry())
    assert square.symmetric_difference(shapely.box(0, 100, 50, 150)).area < 0.01
    assert fences[1].radius_m == 40.0 and fences[1].lonlat == ((items[5].lon, items[5].lat),)
    disc = FRAME.geom_to_local(fences[1].geometry())
    assert disc.centroid.distance(shapely.Point(300, 0)) < 0.01
    # ArduPilot's circle (its flat-earth distance, tests/ardupilot_model.py): every point the
    # vehicle measures within 40 m of the centre lies inside the disc, which is barely more
    c = items[5]
    az = np.radians(np.arange(0.0, 360.0, 1.0))
    for d in (39.9, 40.1):
        # positions at distance d as ArduPilot measures (dlat, dlon scaled at the centre)
        lat = c.lat + d * np.cos(az) / (LATLON_TO_M * 1e7)
        lon = c.lon + d * np.sin(az) / (LATLON_TO_M * 1e7 * math.cos(math.radians(c.lat)))
        measured = location_distance_m(lat, lon, c.lat, c.lon)
        x, y = FRAME.to_local(lon, lat)
        inside = shapely.contains_xy(disc, x, y)
        assert inside[measured < 40.0].all()
    assert 0.98 * math.pi * 40**2 < disc.area < math.pi * 40**2 * 1.002
    assert FRAME.geom_to_local(fences[5].geometry()).area < math.pi * 2000**2


def test_a_self_crossing_polygon_is_its_lobes_and_a_flat_one_bounds_nothing():
    bow = decode_fence(polygon(POLYGON_EXCLUSION, [(0, 0), (100, 100), (100, 0), (0, 100)]))
    lobes = FRAME.geom_to_local(bow[0].geometry())
    assert lobes.is_valid and lobes.area == pytest.approx(5000, rel=1e-3)
    assert lobes.contains(shapely.Point(10, 50)) and not lobes.contains(shapely.Point(50, 10))
    flat = decode_fence(polygon(POLYGON_EXCLUSION, [(0, 0), (0, 0), (0, 0)]))
    assert flat[0].geometry().is_empty


@pytest.mark.parametrize(
    "items, says",
    [
        (polygon(POLYGON_EXCLUSION, [(0, 0), (1, 0), (1, 1)])[:2], "item 0: a polygon of 3"),
        (
            polygon(POLYGON_EXCLUSION, [(0, 0), (1, 0), (1, 1)])[:2]
            + [circle(CIRCLE_EXCLUSION, 0, 0, 5.0)],
            "item 2: a polygon of 3 vertices starting at item 0 is broken by an exclusion circle",
        ),
        (
            polygon(POLYGON_EXCLUSION, [(0, 0), (1, 0)]),
            "item 0: polygon vertex count 2 (3 to 255)",
        ),
        (
            [FenceItem(POLYGON_EXCLUSION, 256.0, 14.5, 35.9)] * 256,
            "item 0: polygon vertex count 256",
        ),
        ([FenceItem(POLYGON_EXCLUSION, 3.5, 14.5, 35.9)] * 4, "item 0: polygon vertex count 3.5"),
        (
            polygon(POLYGON_EXCLUSION, [(0, 0), (1, 0), (1, 1)])[:2]
            + polygon(POLYGON_INCLUSION, [(0, 0), (1, 0), (1, 1)])[:1],
            "item 2: a polygon of 3 vertices starting at item 0 is broken by an inclusion vertex",
        ),
        ([circle(CIRCLE_EXCLUSION, 0, 0, 0.0)], "item 0: circle radius 0 m"),
        ([circle(CIRCLE_EXCLUSION, 0, 0, -3.0)], "item 0: circle radius -3 m"),
        ([circle(CIRCLE_INCLUSION, 0, 0, math.nan)], "item 0: circle radius nan m"),
        ([circle(RETURN_POINT, 0, 0, 0), FenceItem(16, 0, 14.5, 35.9)], "item 1: command 16"),
        ([FenceItem(CIRCLE_EXCLUSION, 5.0, 14.5, 95.0)], "item 0: position 95.0000000"),
        ([SimpleNamespace(command=5004, param1="x", lon=1, lat=2)], "item 0: a field is"),
    ],
)
def test_malformed_fences_are_refused_naming_the_item(items, says):
    with pytest.raises(InputError) as err:
        decode_fence(items)
    assert str(err.value).startswith("the vehicle's fence: ") and says in str(err.value)
    assert "\n" not in str(err.value)


@FUZZ
@given(
    st.lists(
        st.builds(
            SimpleNamespace,
            command=st.one_of(st.sampled_from([5000, 5001, 5002, 5003, 5004]), st.integers()),
            param1=st.one_of(st.floats(), st.integers(0, 300).map(float)),
            lon=st.one_of(st.floats(), st.floats(14.4, 14.6)),
            lat=st.one_of(st.floats(), st.floats(35.8, 36.0)),
        ),
        max_size=20,
    )
)
def test_any_item_list_is_a_fence_or_one_clean_line(items):
    try:
        fences = decode_fence(items)
    except InputError as exc:
        assert "\n" not in str(exc) and "item " in str(exc)
        return
    assert sum(f.last - f.first + 1 for f in fences) <= len(items)
    for f in fences:
        g = f.geometry()
        assert g.is_valid and g.geom_type in ("Polygon", "MultiPolygon")


@FUZZ
@given(
    st.floats(-179.0, 179.0),
    st.floats(-80.0, 80.0),
    st.floats(0.5, 5000.0),
    st.booleans(),
)
def test_a_circle_is_drawn_to_the_safe_side(lon, lat, radius, inclusion):
    """As ArduPilot measures distance (tests/ardupilot_model.py, on 1e-7 degree integers):
    an exclusion's polygon, read in lon/lat, holds every position the vehicle measures
    inside the circle; an inclusion's holds none it measures outside."""
    command = CIRCLE_INCLUSION if inclusion else CIRCLE_EXCLUSION
    (fence,) = decode_fence([FenceItem(command, radius, lon, lat)])
    poly = fence.geometry()
    az = np.arange(0.0, 360.0, 2.0)
    n = az.size
    for scale in (0.98, 0.995, 1.005, 1.02):
        plon, plat, _ = GEOD.fwd(np.full(n, lon), np.full(n, lat), az, np.full(n, radius * scale))
        measured = location_distance_m(plat, plon, lat, lon)
        inside = shapely.contains_xy(poly, plon, plat)
        slack = 0.02  # a centimetre or two: positions are 1e-7 degree integers to the vehicle
        if inclusion:
            assert not inside[measured > radius + slack].any()
        else:
            assert inside[measured < radius - slack].all()
    frame = LocalFrame(lon, lat)  # and not much more (or less) than the circle
    area = frame.geom_to_local(poly).area
    assert math.pi * radius**2 * 0.98 < area < math.pi * radius**2 * 1.02


@FUZZ
@given(st.lists(st.tuples(st.floats(-500, 500), st.floats(-500, 500)), min_size=1, max_size=6))
def test_the_kits_own_items_decode_to_the_fences_they_came_from(centres):
    from alphafence.fencefiles.fence_geojson import FenceRecord

    records = [
        FenceRecord(f"s/{i}", "keep_out", FRAME.geom_to_wgs84(shapely.Point(x, y).buffer(20, 2)))
        for i, (x, y) in enumerate(centres)
    ]
    items = fence_items(records)
    fences = decode_fence(items)
    assert len(fences) == len(records)
    for f, r in zip(fences, records):
        a, b = FRAME.geom_to_local(f.geometry()), FRAME.geom_to_local(r.geometry)
        assert a.symmetric_difference(b).area < 1e-3 * b.area


def test_a_circle_too_small_for_degrees_has_no_area():
    # found by the fuzz test above: a 3e-37 m radius collapsed to one repeated point (invalid)
    item = SimpleNamespace(command=5003, param1=3.3759425731685346e-37, lon=0.0, lat=0.0)
    (fence,) = decode_fence([item])
    assert fence.geometry().is_empty and fence.geometry().is_valid
