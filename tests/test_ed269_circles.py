"""Circle zones fenced by circles: a site that is one ED-269 or ED-318 circle, one KML point
with a radius or one OpenAir DC circle gets one circle fence (one circle item onboard, 13
bytes) instead of a 32-gon (258 of a copter's 560 bytes), its radius the zone's plus the
margin; sites of several zones keep polygon fences."""

import json
from pathlib import Path

import numpy as np
import pytest
import shapely
from pyproj import Geod

from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.tiled import build_tiled
from alphafence.mavlink.items import CIRCLE_EXCLUSION, CIRCLE_INCLUSION, fence_items
from alphafence.mavlink.storage import CIRCLE_BYTES, END_BYTES, HEADER_BYTES, PROFILES
from alphafence.onboard.compile import compile_fences
from alphafence.zones.database import DatabaseStream, read_database
from alphafence.zones.rules import parse_rules

from .ardupilot_model import location_distance_m

DATA = Path(__file__).parent / "data"
GEOD = Geod(ellps="WGS84")


def geodesic_m(lon0, lat0, lon1, lat1):
    return GEOD.inv(lon0, lat0, lon1, lat1)[2]


def zone_fences(result, source):
    """The fences of the site whose only member is ``source``, by kind."""
    return {f.kind: f for f in result.fences if f.sources == [source]}


def assert_circle_fence(fence, lon, lat, radius_m, margin_m):
    """A circle about the zone's centre, as large as the zone plus margin and barely more
    (the reader's polygon lies within 0.13 % + 1.5 m of the zone's circle)."""
    assert fence.circle is not None and fence.method == "circle"
    clon, clat, r = fence.circle_wgs84
    assert geodesic_m(lon, lat, clon, clat) < 0.01
    assert radius_m + margin_m <= r <= radius_m * 1.0013 + margin_m + 1.7


def assert_vehicle_circle_holds(item, lon, lat, radius_m, outward=True):
    """ArduPilot's circle of ``item`` (its own distance, :mod:`tests.ardupilot_model`)
    contains the geodesic circle of ``radius_m`` about ``(lon, lat)`` (or lies inside it)."""
    az = np.arange(0.0, 360.0, 0.25)
    plon, plat, _ = GEOD.fwd(np.full(az.size, lon), np.full(az.size, lat), az,
                             np.full(az.size, radius_m))  # fmt: skip
    d = location_distance_m(plat, plon, item.lat, item.lon)
    if outward:
        assert d.max() < item.param1, f"ArduPilot reads the zone {d.max() - item.param1:.2f} m out"
    else:
        assert d.min() > item.param1, (
            f"ArduPilot's circle reaches {item.param1 - d.min():.2f} m out"
        )


def test_a_one_circle_ed269_file_is_one_circle_item_for_a_copter(rules):
    """The issue's file: one 1000 ft circle. 32 items, 258 bytes of 560 before; one item now."""
    db = read_database([DATA / "ed269" / "feet-circle.json"], rules)
    result = build_fences(db.features, rules)
    fences = zone_fences(result, "FT-C01")
    (zone,) = [f for f in db.features if f.source == "FT-C01"]
    margin = zone.rule.margin_m  # the rules' geozone margin
    assert_circle_fence(fences["keep_out"], 8.5421, 47.3769, 304.8, margin)
    assert fences["warning"].circle is not None  # its warning layer: a circle 30 m further
    assert fences["warning"].circle[2] == pytest.approx(fences["keep_out"].circle[2] + 30.0)
    (item,) = fence_items([fences["keep_out"]])
    assert item.command == CIRCLE_EXCLUSION
    # the item's radius as ArduPilot measures distance: the zone plus margin (a geodesic
    # circle) lies inside it, and it is no more than 0.7 % larger than the fence's radius
    assert_vehicle_circle_holds(item, 8.5421, 47.3769, 304.8 + margin)
    assert fences["keep_out"].circle[2] <= item.param1 <= fences["keep_out"].circle[2] * 1.007
    box = shapely.box(8.53, 47.37, 8.55, 47.385)
    onboard = compile_fences(result.fences, box, PROFILES["copter"])
    assert [p.chosen.kind for p in onboard.pieces] == ["circle"]
    assert len(onboard.items) == 1 and onboard.items[0].command == CIRCLE_EXCLUSION
    assert onboard.bytes_used == HEADER_BYTES + CIRCLE_BYTES + END_BYTES  # 18 (was 263)


def test_an_ed318_point_with_a_circle_extent(rules):
    db = read_database([DATA / "ed269" / "ed318.json"], rules)
    fences = zone_fences(build_fences(db.features, rules), "E318C2")
    (zone,) = [f for f in db.features if f.source == "E318C2"]
    assert_circle_fence(fences["keep_out"], 8.6201, 47.4101, 500.0, zone.rule.margin_m)
    # the polygon zone of the same file stays a polygon
    assert zone_fences(build_fences(db.features, rules), "E318P1")["keep_out"].circle is None


def test_a_kml_point_with_a_radius_and_an_openair_dc_circle(rules):
    db = read_database([DATA / "kml" / "google-earth.kml"], rules)
    (helipad,) = [f for f in db.features if f.name == "Hospital helipad"]
    fences = zone_fences(build_fences(db.features, rules), helipad.source)
    margin = helipad.rule.margin_m
    assert_circle_fence(fences[helipad.kind], 14.47833, 35.90154, 150.0, margin)
    db = read_database([DATA / "openair" / "sample.openair"], rules)
    (prison,) = [f for f in db.features if f.name == "EGP998 PRISON"]
    fences = zone_fences(build_fences(db.features, rules), prison.source)
    centre = (-(1 + 20 / 60), 52 + 10 / 60)
    assert_circle_fence(fences["keep_out"], *centre, 1.5 * 1852.0, prison.rule.margin_m)


def ed269_doc(*zones):
    """ED-269 zones ``(identifier, lon, lat, radius_m, restriction)`` as InterUSS writes them."""
    return {
        "title": "circles",
        "features": [
            {
                "identifier": ident,
                "country": "CHE",
                "name": ident,
                "type": "COMMON",
                "restriction": restriction,
                "reason": ["OTHER"],
                "applicability": [{"permanent": "YES"}],
                "geometry": [
                    {
                        "uomDimensions": "M",
                        "lowerLimit": 0,
                        "lowerVerticalReference": "AGL",
                        "upperLimit": 120,
                        "upperVerticalReference": "AGL",
                        "horizontalProjection": {
                            "type": "Circle",
                            "center": [lon, lat],
                            "radius": radius,
                        },
                    }
                ],
            }
            for ident, lon, lat, radius, restriction in zones
        ],
    }


def test_a_site_of_several_circle_zones_keeps_its_polygon_fence(tmp_path, rules):
    path = tmp_path / "two.json"
    doc = ed269_doc(("A", 8.5, 47.3, 200, "PROHIBITED"), ("B", 8.503, 47.3, 200, "PROHIBITED"))
    path.write_text(json.dumps(doc))
    db = read_database([path], rules)
    result = build_fences(db.features, rules)
    (main,) = [f for f in result.fences if f.kind == "keep_out"]
    assert main.sources == ["A", "B"] and main.circle is None and main.method == "alpha"


def test_a_keep_in_circle_zone_is_a_circle_inside_it(tmp_path):
    rules = parse_rules(
        {
            "rule": [
                {
                    "category": "allowed",
                    "kind": "keep_in",
                    "tags": {"ed269:restriction": "NO_RESTRICTION"},
                    "margin_m": 20.0,
                }
            ]
        }
    )
    path = tmp_path / "keep-in.json"
    path.write_text(json.dumps(ed269_doc(("K", -3.2, 55.9, 800, "NO_RESTRICTION"))))
    result = build_fences(read_database([path], rules).features, rules)
    (fence,) = result.fences
    assert fence.kind == "keep_in" and fence.circle is not None
    clon, clat, r = fence.circle_wgs84
    assert geodesic_m(-3.2, 55.9, clon, clat) < 0.01
    assert 800 - 20 - 0.2 <= r <= 800 - 20  # inside the zone, the margin from its edge
    (item,) = fence_items([fence])
    assert item.command == CIRCLE_INCLUSION


def test_circle_zones_survive_the_spool_and_tiles(tmp_path, rules):
    """The tiled build pickles features through its spool: the zone's circle comes back."""
    path = tmp_path / "zones.json"
    doc = ed269_doc(
        ("A", 8.5, 47.3, 200, "PROHIBITED"),
        ("B", 8.6, 47.3, 350, "REQ_AUTHORISATION"),
        ("C", 8.7, 47.35, 90, "CONDITIONAL"),
    )
    path.write_text(json.dumps(doc))
    options = BuildOptions()
    untiled = build_fences(read_database([path], rules).features, rules, options)
    tiled = build_tiled(DatabaseStream([str(path)], rules), rules, options, jobs=1, keep=True)
    want = {(f.site_id, f.kind): f.circle for f in untiled.fences}
    assert {(f.site_id, f.kind): f.circle for f in tiled.fences} == want
    assert all(c is not None for c in want.values()) and len(want) == 5  # C: a warning site


def test_a_circle_zones_warning_rule_gets_a_circle(tmp_path, rules):
    """A CONDITIONAL zone is a warning site: its fence is a circle as well."""
    path = tmp_path / "warn.json"
    path.write_text(json.dumps(ed269_doc(("W", 14.5, 35.9, 120, "CONDITIONAL"))))
    fences = zone_fences(build_fences(read_database([path], rules).features, rules), "W")
    assert_circle_fence(fences["warning"], 14.5, 35.9, 120.0, 10.0)
