"""ED-269 (and ED-318) files written the way InterUSS, EUROCAE and authorities write them:
feet, the UASZoneList wrapper, numbers given as strings, the successor format, and zones that
must never share one fence (time windows, restriction, altitude band, reference)."""

import json
from collections import Counter
from datetime import datetime, timezone
from pathlib import Path

import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.fencing.pipeline import build_fences
from alphafence.geo.frame import LocalFrame
from alphafence.zones.database import read_database
from alphafence.zones.ed269 import read_ed269_doc
from alphafence.zones.rules import load_rules

DATA = Path(__file__).parent / "data" / "ed269"


def load(name):
    return json.loads((DATA / name).read_text())


def local_radius(feature, lon, lat):
    """The largest distance (m) from (lon, lat) to the feature's outline."""
    local = LocalFrame(lon, lat).geom_to_local(feature.geometry)
    return shapely.hausdorff_distance(local, shapely.Point(0, 0))


# -- 2: a circle's radius in feet ------------------------------------------------------


def test_a_circle_radius_in_feet_is_converted(rules):
    (zone,) = read_database([DATA / "feet-circle.json"], rules).features
    assert zone.alt_min_m == 0 and zone.alt_max_m == pytest.approx(400 * 0.3048)
    # 1000 ft is 304.8 m: the polygon circumscribes that circle, not a 1000 m one
    r = local_radius(zone, 8.5421, 47.3769)
    assert 304.8 <= r < 304.8 * 1.01
    local = LocalFrame(8.5421, 47.3769).geom_to_local(zone.geometry)
    assert local.covers(shapely.Point(0, 0).buffer(304.79, quad_segs=64))
    assert zone.properties["circle"] == [8.5421, 47.3769, pytest.approx(304.8)]


# -- 3: layouts --------------------------------------------------------------------------


def test_the_uaszonelist_wrapper_and_limits_given_as_strings_are_read(rules):
    db = read_database([DATA / "uaszonelist.json"], rules)
    got = {f.source: f for f in db.features}
    assert set(got) == {"ZL-P01", "ZL-C02"}
    assert got["ZL-P01"].alt_min_m == 0 and got["ZL-P01"].alt_max_m == 120
    assert got["ZL-C02"].alt_max_m == 150.5 and got["ZL-C02"].kind == "keep_out"
    assert 300 <= local_radius(got["ZL-C02"], 8.5601, 47.3851) < 303


@pytest.mark.parametrize("bad", ["ten", "", "nan", "inf", "1e400", [120], True])
def test_a_limit_that_is_no_number_is_one_line(write_json, rules, bad):
    doc = load("uaszonelist.json")
    doc["UASZoneList"][1]["geometry"][0]["upperLimit"] = bad
    with pytest.raises(InputError) as exc:
        read_database([write_json("zones.json", doc)], rules)
    msg = str(exc.value)
    assert "\n" not in msg and "zones.json" in msg and "ZL-C02" in msg and "upperLimit" in msg


def test_an_empty_uaszonelist_is_no_restricted_features_not_a_geojson_error(write_json, rules):
    path = write_json("empty.json", {"formatVersion": "1.0.0", "UASZoneList": []})
    with pytest.raises(InputError, match="no restricted features"):
        read_database([path], rules)


def test_ed318_zones_are_read(rules):
    db = read_database([DATA / "ed318.json"], rules)
    got = {f.source: f for f in db.features}
    assert set(got) == {"E318P1", "E318C2"}  # the U-space zone restricts nothing by itself
    assert any("USPACE" in reason for reason in db.skipped)
    prison, heliport = got["E318P1"], got["E318C2"]
    assert prison.kind == heliport.kind == "keep_out"
    assert prison.name == "Prison Lenzwil" and heliport.name == "Heliport Aarfeld"
    assert prison.geometry.equals(shapely.box(8.6001, 47.4001, 8.6041, 47.4031))
    assert (prison.alt_min_m, prison.alt_max_m) == (0, 120)
    assert prison.properties["upper_reference"] == "AGL" and prison.properties["reason"] == [
        "SENSITIVE"
    ]
    # a Point with a Circle extent (radius in metres); the layer in feet
    assert 500 <= local_radius(heliport, 8.6201, 47.4101) < 505
    assert heliport.alt_max_m == pytest.approx(1000 * 0.3048)
    assert heliport.properties["upper_reference"] == "AMSL"
    assert heliport.properties["lower_reference"] == "AGL"
    assert heliport.properties["restriction"] == "REQ_AUTHORISATION"
    assert heliport.properties["applicability"][0]["schedule"][0]["day"][0] == "MON"


def test_ed318_layout_variants(write_json, rules):
    doc = load("ed318.json")
    prison = doc["features"][0]
    # uas_standards also reads the zone nested under UASZone and the layer in the properties
    nested = {
        "type": "Feature",
        "properties": {
            "UASZone": prison["properties"],
            "verticalLayer": prison["geometry"].pop("layer"),
        },
        "geometry": prison["geometry"],
    }
    db = read_database([write_json("nested.json", {**doc, "features": [nested]})], rules)
    (zone,) = db.features
    assert zone.source == "E318P1" and zone.alt_max_m == 120


@pytest.mark.parametrize(
    "change, expected",
    [
        (lambda z: z["geometry"].update(type="LineString"), "LineString"),
        (lambda z: z["geometry"].update(type="Point", coordinates=[8.6, 47.4]), "extent"),
        (lambda z: z["geometry"]["layer"].update(uom="furlong"), "uom"),
        (lambda z: z["geometry"]["layer"].update(upper="high"), "upper"),
        (lambda z: z["properties"].pop("type"), "type"),
    ],
)
def test_bad_ed318_is_one_line(write_json, rules, change, expected):
    doc = load("ed318.json")
    change(doc["features"][0])
    with pytest.raises(InputError) as exc:
        read_database([write_json("zones.json", doc)], rules)
    msg = str(exc.value)
    assert "\n" not in msg and "E318P1" in msg and expected in msg


def test_a_file_that_adds_nothing_is_said_when_several_are_read(write_json, rules):
    quiet = load("uaszonelist.json")
    for zone in quiet["UASZoneList"]:
        zone["restriction"] = "NO_RESTRICTION"
    path = write_json("quiet.json", quiet)
    db = read_database([DATA / "feet-circle.json", path], rules)
    assert [f.source for f in db.features] == ["FT-C01"]
    assert any("quiet.json" in reason for reason in db.skipped)


@pytest.mark.parametrize(
    "key, value",
    [
        ("uomDimensions", []),  # was a TypeError (a list is unhashable)
        ("uomDimensions", "furlong"),
        ("horizontalProjection", {"type": "Circle", "center": [10**400, 47.0], "radius": 5}),
        (
            "horizontalProjection",  # was an OverflowError from shapely
            {"type": "Polygon", "coordinates": [[[10**400, 47], [8, 47], [8, 48], [10**400, 47]]]},
        ),
        ("horizontalProjection", {"type": "Circle", "center": [8.5, 47.4], "radius": "ten"}),
    ],
)
def test_odd_values_are_one_line(tmp_path, rules, key, value):
    doc = load("feet-circle.json")
    doc["features"][0]["geometry"][0][key] = value
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as exc:
        read_database([path], rules)
    msg = str(exc.value)
    assert "\n" not in msg and "zones.json" in msg and "FT-C01" in msg


# -- 1 and 8: zones that differ in force, restriction, band or reference never share a fence


def build(path, rules, tmp_path):
    from alphafence.cli import main

    out = tmp_path / "fences.geojson"
    assert main(["build", str(path), "-o", str(out), "-q"]) == 0
    return [f["properties"] for f in json.loads(out.read_text())["features"]]


def test_a_permanent_preserve_stays_in_force_beside_a_weekend_concert(rules, tmp_path):
    from alphafence.awareness.applicability import is_active

    fences = [p for p in build(DATA / "preserve-concert.json", rules, tmp_path)]
    keep_out = {tuple(p["sources"]): p for p in fences if p["kind"] == "keep_out"}
    assert set(keep_out) == {("NAT-01",), ("EVT-07",)}
    wednesday = datetime(2025, 7, 2, 12, 0, tzinfo=timezone.utc)
    saturday_night = datetime(2025, 7, 5, 20, 0, tzinfo=timezone.utc)
    preserve, concert = keep_out[("NAT-01",)], keep_out[("EVT-07",)]
    assert is_active(preserve["zone"]["applicability"], wednesday)
    assert not is_active(concert["zone"]["applicability"], wednesday)
    assert is_active(concert["zone"]["applicability"], saturday_night)
    assert preserve["zone"]["reason"] == ["NATURE"] and concert["zone"]["reason"] == ["POPULATION"]


def test_nested_altitude_bands_stay_three_fences_with_their_bands(rules, tmp_path):
    fences = build(DATA / "nested-bands.json", rules, tmp_path)
    bands = sorted(
        (p["alt_min_m"], p["alt_max_m"], p["sources"][0]) for p in fences if p["kind"] == "keep_out"
    )
    assert bands == [(0, 120, "BND-00"), (50, 120, "BND-50"), (100, 120, "BND-100")]
    assert all(p["zone"]["lower_reference"] == "AGL" for p in fences)


def test_a_height_and_an_altitude_limit_are_never_one_ceiling(rules, tmp_path):
    fences = build(DATA / "agl-amsl.json", rules, tmp_path)
    keep_out = {p["sources"][0]: p for p in fences if p["kind"] == "keep_out"}
    assert set(keep_out) == {"REF-AG", "REF-AM"}
    assert keep_out["REF-AG"]["alt_max_m"] == 120
    assert keep_out["REF-AG"]["zone"]["upper_reference"] == "AGL"
    assert keep_out["REF-AM"]["alt_max_m"] == 500
    assert keep_out["REF-AM"]["zone"]["upper_reference"] == "AMSL"


WEEKEND = [
    {
        "permanent": "NO",
        "startDateTime": "2025-07-04T00:00:00Z",
        "endDateTime": "2025-07-07T00:00:00Z",
        "schedule": [{"day": ["SAT", "SUN"], "startTime": "14:00:00Z", "endTime": "23:00:00Z"}],
    }
]
NOVEMBER = [
    {
        "permanent": "NO",
        "startDateTime": "2026-11-01T00:00:00Z",
        "endDateTime": "2026-12-01T00:00:00Z",
    }
]
attributes = st.fixed_dictionaries(
    {
        "restriction": st.sampled_from(["PROHIBITED", "REQ_AUTHORISATION"]),
        "applicability": st.sampled_from(["permanent", "weekend", "november"]),
        "band": st.sampled_from([(0, 120), (50, 120), (0, 150)]),
        "lower_reference": st.sampled_from(["AGL", "AMSL"]),
        "upper_reference": st.sampled_from(["AGL", "AMSL"]),
    }
)
zones = st.lists(
    st.tuples(
        attributes,
        st.floats(-80, 80),  # centre offsets, metres: every pair of circles overlaps
        st.floats(-80, 80),
        st.floats(200, 400),  # radius, metres
        st.sampled_from(["M", "FT"]),
    ),
    min_size=2,
    max_size=5,
)


def zone_doc(drawn):
    feats = []
    for i, (attrs, dx, dy, radius, uom) in enumerate(drawn):
        scale = 0.3048 if uom == "FT" else 1.0
        lower, upper = attrs["band"]
        feats.append(
            {
                "identifier": f"Z{i}",
                "country": "CHE",
                "name": f"zone {i}",
                "type": "COMMON",
                "restriction": attrs["restriction"],
                "reason": ["OTHER"],
                "zoneAuthority": [{"purpose": "INFORMATION"}],
                "applicability": {
                    "permanent": [{"permanent": "YES"}],
                    "weekend": WEEKEND,
                    "november": NOVEMBER,
                }[attrs["applicability"]],
                "geometry": [
                    {
                        "uomDimensions": uom,
                        "lowerLimit": lower / scale,
                        "lowerVerticalReference": attrs["lower_reference"],
                        "upperLimit": upper / scale,
                        "upperVerticalReference": attrs["upper_reference"],
                        "horizontalProjection": {
                            "type": "Circle",
                            "center": [8.8 + dx / 75_000.0, 47.5 + dy / 111_200.0],
                            "radius": radius / scale,
                        },
                    }
                ],
            }
        )
    return {"title": "random overlapping zones", "features": feats}


def attributes_of(zone_properties):
    return (
        zone_properties["restriction"],
        json.dumps(zone_properties["applicability"], sort_keys=True),
        zone_properties["lower_reference"],
        zone_properties["upper_reference"],
    )


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(zones)
def test_zones_share_a_fence_only_when_equal_in_force_restriction_band_and_reference(drawn):
    rules = load_rules()
    doc = zone_doc(drawn)
    features = read_ed269_doc("random.json", doc, rules, [], Counter())
    expected = Counter(
        (*attributes_of(f.properties), round(f.alt_min_m, 3), round(f.alt_max_m, 3))
        for f in features
    )
    result = build_fences(features, rules)
    keys_seen = []
    for site in result.sites:
        keys = {
            (*attributes_of(f.properties), round(f.alt_min_m, 3), round(f.alt_max_m, 3))
            for f in site.features
        }
        assert len(keys) == 1, keys  # never two kinds of zone in one site
        (key,) = keys
        keys_seen.append(key)
        # the site's band is its zones' band, not a union of others
        assert (round(site.alt_min_m, 3), round(site.alt_max_m, 3)) == key[-2:]
    # every circle overlaps every other: equal zones merge, so one site per kind of zone
    assert sorted(keys_seen) == sorted(expected)
    for fence in result.fences:
        site = next(s for s in result.sites if s.site_id == fence.site_id)
        member = site.features[0].properties
        assert fence.properties["applicability"] == member["applicability"]
        assert fence.properties["restriction"] == member["restriction"]
        assert fence.properties["upper_reference"] == member["upper_reference"]
        assert (fence.alt_min_m, fence.alt_max_m) == (site.alt_min_m, site.alt_max_m)
