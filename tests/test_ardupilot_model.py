"""The model of ArduPilot's fence (tests/ardupilot_model.py) against cases worked by hand from
ArduPilot's source (``AC_PolyFence_loader::breached``, ``Location::get_distance``,
``Polygon_outside``), and the kit's own reading of a vehicle's fence against the model.
SITL's own verdicts are compared in tests/test_inclusions_sitl.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.mavlink.items import FenceItem
from alphafence.onboard.decode import breached as kit_breached
from alphafence.onboard.decode import decode_fence

from .ardupilot_model import LATLON_TO_M, breached, location_distance_m, polygon_outside


def square(command, lon0, lat0, size):
    corners = ((0, 0), (size, 0), (size, size), (0, size))
    return [FenceItem(command, 4.0, lon0 + x, lat0 + y) for x, y in corners]


def test_distance_scales_longitude_at_the_mean_latitude():
    # Location::get_distance: dlat = 1e6, dlng = 1e6 * cos((600000000 + 601000000) / 2 * 1e-7 deg)
    expected = math.hypot(1e6, 1e6 * math.cos(math.radians(60.05))) * 0.011131884502145034
    got = float(location_distance_m(60.1, 0.1, 60.0, 0.0)[()])
    assert got == pytest.approx(expected, abs=1e-6)
    at_centre = float(location_distance_m(60.1, 0.1, 60.0, 0.0, mean=False)[()])
    assert at_centre - got > 3.0  # cos(60.0) > cos(60.05): the centre's scale reads longer


def test_distance_mean_latitude_is_an_integer_division():
    # (lat + loc2.lat) / 2 on int32 truncates toward zero. Far from the equator half a unit of
    # latitude moves the longitude scale by tan(lat) * 0.5e-7 deg, which over a long east-west
    # distance is tens of micrometres: the case is worked at 60 degrees, 1 degree of longitude
    # apart, on both sides of the equator (where truncation and flooring part)
    for sign in (1, -1):
        a_lat, c_lat = sign * 600_000_001, sign * 600_000_002  # 1e-7 degrees
        mean = int((a_lat + c_lat) / 2)  # C's division: toward zero
        assert mean == sign * 600_000_001

        def at(m):
            dlon = 10_000_000 * math.cos(math.radians(m * 1e-7))
            return math.hypot(1, dlon) * LATLON_TO_M  # 1e-7 degrees of latitude apart

        got = float(location_distance_m(a_lat * 1e-7, 1.0, c_lat * 1e-7, 0.0)[()])
        assert got == pytest.approx(at(mean), rel=1e-13)
        # the cases tell the rule apart: an exact mean, or flooring, misses by far more
        for wrong in ((a_lat + c_lat) / 2, (a_lat + c_lat) // 2, c_lat):
            if wrong != mean:
                assert abs(at(wrong) - got) > 1e-12 * got * 100


def test_distance_constant_is_a_6378100_m_sphere():
    assert LATLON_TO_M * 1e7 == pytest.approx(6_378_100 * math.pi / 180, rel=1e-9)
    assert float(location_distance_m(0.001, 0.0, 0.0, 0.0)[()]) == pytest.approx(
        111.3188450, abs=1e-6
    )


def test_polygon_edges_south_inside_north_outside():
    # Polygon_outside with P.x = lat, P.y = lng, worked by hand for the square lat, lng in
    # [0, 1e7]: an edge counts where it straddles P.y; on the south edge the crossing of the
    # north edge flips (dx1 * dy2 > dx2 * dy1 with dy2 < 0), on the north edge nothing does
    ring_lat, ring_lon = [0.0, 0.0, 1.0, 1.0], [0.0, 1.0, 1.0, 0.0]
    lat = np.array([0.0, 1.0, 0.5, 0.5, 1.0000001, -0.0000001])
    lon = np.array([0.5, 0.5, 0.5, 1.5, 0.5, 0.5])
    assert polygon_outside(lat, lon, ring_lat, ring_lon).tolist() == [
        False, True, False, True, True, True,
    ]  # fmt: skip


def test_inclusions_intersect_unless_union():
    west = square(5001, 0.0, 0.0, 0.01)
    east = square(5001, 0.005, 0.0, 0.01)  # overlapping west's eastern half
    items = west + east
    lon = np.array([0.002, 0.007, 0.012, 0.02])
    lat = np.full(4, 0.005)
    assert breached(items, lon, lat).tolist() == [True, False, True, True]
    assert breached(items, lon, lat, union=True).tolist() == [False, False, False, True]


def test_exclusions_breach_under_either_rule():
    items = square(5001, 0.0, 0.0, 0.01) + [FenceItem(5004, 100.0, 0.005, 0.005)]
    lon, lat = np.array([0.005, 0.0005]), np.array([0.005, 0.0005])
    for union in (False, True):
        assert breached(items, lon, lat, union).tolist() == [True, False]


def test_circle_edges_as_compared():
    # an inclusion circle is left above its radius, an exclusion entered below it
    r = float(location_distance_m(0.001, 0.0, 0.0, 0.0)[()])
    on_rim = (np.array([0.0]), np.array([0.001]))
    assert not breached([FenceItem(5003, r, 0.0, 0.0)], *on_rim)[0]
    assert not breached([FenceItem(5004, r, 0.0, 0.0)], *on_rim)[0]
    assert breached([FenceItem(5003, r - 0.001, 0.0, 0.0)], *on_rim)[0]
    assert breached([FenceItem(5004, r + 0.001, 0.0, 0.0)], *on_rim)[0]


def test_no_inclusion_under_union_is_no_breach():
    items = [FenceItem(5004, 50.0, 1.0, 1.0)]
    assert not breached(items, [0.0], [0.0], union=True)[0]


def test_broken_model_is_seen():
    """The hand-worked cases fail on a model that reads inclusions as "inside any" without
    the option (the tests' old model, which hid the kit's two-area fence)."""
    west, east = square(5001, 0.0, 0.0, 0.01), square(5001, 0.05, 0.0, 0.01)
    wrong = breached(west + east, [0.005], [0.005], union=True)  # what "any" says
    assert wrong.tolist() != breached(west + east, [0.005], [0.005]).tolist()


shapes = st.lists(
    st.tuples(
        st.sampled_from([5001, 5002, 5003, 5004]),
        st.floats(-0.02, 0.02),
        st.floats(-0.02, 0.02),
        st.floats(0.001, 0.02),
    ),
    min_size=1,
    max_size=5,
)


@settings(max_examples=60, deadline=None)
@given(shapes, st.booleans(), st.floats(-60.0, 60.0))
def test_kit_reads_a_fence_as_the_model(parts, union, lat0):
    """The monitor's and upload's reading (``alphafence.onboard.decode.breached``) gives the
    model's verdict at every sampled position."""
    items = []
    for cmd, x, y, size in parts:
        if cmd in (5003, 5004):
            items.append(FenceItem(cmd, size * 1e5, x, lat0 + y))
        else:
            items += square(cmd, x, lat0 + y, size)
    fences = decode_fence(items)
    rng = np.random.default_rng(len(items))
    lon = rng.uniform(-0.03, 0.05, 40)
    lat = lat0 + rng.uniform(-0.03, 0.05, 40)
    want = breached(items, lon, lat, union)
    got = [kit_breached(fences, a, b, union) for a, b in zip(lon, lat)]
    assert got == want.tolist()


@pytest.mark.parametrize("lat", [0.0, 35.9, 64.0, 78.0])
@pytest.mark.parametrize("radius", [150.0, 5_000.0, 100_000.0])
def test_circle_items_hold_under_either_distance_reading(lat, radius):
    """An exclusion item contains the geodesic circle and an inclusion item lies inside it,
    read by current ArduPilot (mean latitude) and by firmware scaling at the centre; an
    inclusion a metre larger, or sized by the centre's reading alone, is seen to reach out."""
    from alphafence.geo.vehicle_distance import vehicle_radius

    from .ardupilot_model import GEOD

    az = np.arange(0.0, 360.0, 0.25)
    n = az.size
    plon, plat, _ = GEOD.fwd(np.full(n, 14.5), np.full(n, lat), az, np.full(n, radius))
    out = vehicle_radius(14.5, lat, radius, outward=True)
    inward = vehicle_radius(14.5, lat, radius, outward=False)
    for mean in (True, False):
        d = location_distance_m(plat, plon, lat, 14.5, mean=mean)
        assert d.max() < out and d.min() > inward
    # sized as the kit sized it before (the centre's latitude, a 6,378,137 m sphere), a large
    # inclusion reaches past its geodesic circle as current ArduPilot measures
    if radius >= 100_000.0 and lat == 0.0:  # where the constants differ most, unscaled
        from alphafence.geo.vehicle_distance import LEGACY_LATLON_TO_M, vehicle_distance_m

        before = vehicle_distance_m(plon, plat, 14.5, lat, False, LEGACY_LATLON_TO_M).min()
        assert location_distance_m(plat, plon, lat, 14.5).min() < before * (1 - 1e-6) - 0.01


def test_the_kits_reading_agrees_with_the_model_written_from_ardupilots_source():
    """The kit's vectorised breach check (``geo.vehicle_distance``) and this model, written
    apart from it, agree on random positions, rings and circles (Malta and the antimeridian)."""
    import numpy as np

    from alphafence.geo import vehicle_distance as kit

    from .ardupilot_model import location_distance_m, polygon_outside

    rng = np.random.default_rng(7)
    for lon0, lat0 in ((14.5, 35.9), (179.99, -16.5), (-0.5, 51.4)):
        ring_lon = lon0 + rng.uniform(-0.01, 0.01, 9)
        ring_lat = lat0 + rng.uniform(-0.01, 0.01, 9)
        lon = lon0 + rng.uniform(-0.012, 0.012, 5000)
        lat = lat0 + rng.uniform(-0.012, 0.012, 5000)
        model = polygon_outside(lat, lon, ring_lat, ring_lon)
        assert (kit.polygon_outside(lon, lat, ring_lon, ring_lat) == model).all()
        for mean in (True, False):
            d = location_distance_m(lat, lon, lat0, lon0, mean=mean)
            assert np.allclose(kit.vehicle_distance_m(lon, lat, lon0, lat0, mean=mean), d,
                               rtol=1e-12, atol=1e-9)  # fmt: skip


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-80.0, 80.0),
    st.floats(-180.0, 180.0),
    st.floats(0.0, 360.0),
    st.floats(1.0, 100_000.0),
)
def test_the_kits_distance_is_arduPilots_to_the_micrometre(clat, clon, bearing, dist):
    """``alphafence.geo.vehicle_distance.vehicle_distance_m`` against the model, written apart
    from it, for positions up to 100 km from a centre anywhere: equal to a part in 1e12. A
    kit that scales longitude at the centre's latitude misses by up to 1e-4 of the distance."""
    from alphafence.geo.vehicle_distance import vehicle_distance_m

    from .ardupilot_model import GEOD

    lon, lat, _ = GEOD.fwd(clon, clat, bearing, dist)
    model = float(location_distance_m(lat, lon, clat, clon)[()])
    kit = float(vehicle_distance_m(lon, lat, clon, clat))
    assert kit == pytest.approx(model, rel=1e-12, abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(20.0, 80.0), st.booleans(), st.floats(5_000.0, 100_000.0), st.booleans())
def test_the_kit_breaches_a_circle_where_arduPilot_does(lat, south, radius, inclusion):
    """At diagonal bearings just inside and just outside the model's rim of a circle item (a
    part in 1e6 and 3 cm either way), the kit's breach check gives ArduPilot's verdict; there a
    centre-latitude reading is off by decimetres to tens of metres."""
    from .ardupilot_model import circle_rim

    clat = -lat if south else lat
    item = FenceItem(5003 if inclusion else 5004, radius, 14.5, clat)
    fences = decode_fence([item])
    for scale, slack in ((1.0 - 1e-6, -0.03), (1.0 + 1e-6, 0.03)):
        rlon, rlat = circle_rim(14.5, clat, radius * scale + slack, n=8)
        diagonal = slice(1, None, 2)  # 45, 135, 225, 315 degrees
        rlon, rlat = rlon[diagonal], rlat[diagonal]
        want = breached([item], rlon, rlat)
        got = [kit_breached(fences, a, b, False) for a, b in zip(rlon, rlat)]
        assert got == want.tolist()
        assert want.tolist() == [inclusion == (scale > 1.0)] * 4  # the model's rim is its own


@pytest.mark.parametrize("model", ["ardupilot_model.py", "px4_model.py"])
def test_the_models_import_nothing_from_the_kit(model):
    """The autopilots' models share no code with the kit: a distance or rule bug in the kit
    cannot move the model with it. Read from the module's syntax tree (imports anywhere in it,
    functions included), and from a fresh interpreter that imports the model alone."""
    import ast
    import subprocess
    import sys
    from pathlib import Path

    here = Path(__file__).parent
    tree = ast.parse((here / model).read_text())
    named = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    named |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not [m for m in named if m.split(".")[0] == "alphafence"], named
    probe = (
        f"import sys; import tests.{model[:-3]}; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'alphafence'))"
    )
    out = subprocess.run([sys.executable, "-c", probe], cwd=here.parent, capture_output=True,
                         text=True, check=True)  # fmt: skip
    assert out.stdout.strip() == "[]", out.stdout
