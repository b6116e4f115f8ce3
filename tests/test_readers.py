"""Reading geofence databases: OSM (Malta), QGIS-shaped GeoJSON, ED-269, and bad input."""

import collections
import shutil

import pytest
import shapely

from alphafence.errors import InputError
from alphafence.geo.frame import LocalFrame
from alphafence.zones.database import read_database
from alphafence.zones.geojson import parse_hstore, tags_of


def test_malta_has_its_known_restricted_places(malta_db):
    by_source = {f.source: f for f in malta_db.features}
    airport = by_source["way/23541031"]
    assert airport.category == "aerodrome" and airport.kind == "keep_out"
    assert airport.name == "Ajruport Internazzjonali ta' Malta"
    assert by_source["way/24063943"].category == "hospital"  # Mater Dei
    assert by_source["way/24274135"].category == "prison"  # Kordin
    assert by_source["way/15683546"].category == "power"  # Delimara
    kinds = collections.Counter((f.category, f.geomtype) for f in malta_db.features)
    assert kinds[("school", "area")] > 100 and kinds[("military", "area")] > 10
    # areas are polygons, tagged nodes points, each in Malta's bounding box
    assert airport.geometry.geom_type in ("Polygon", "MultiPolygon")
    assert by_source["node/3890806957"].geometry.geom_type == "Point"
    minx, miny, maxx, maxy = shapely.total_bounds([f.geometry for f in malta_db.features])
    assert 13.8 < minx < maxx < 14.9 and 35.5 < miny < maxy < 36.4


def test_airport_area_is_about_right(malta_db):
    airport = next(f for f in malta_db.features if f.source == "way/23541031")
    frame = LocalFrame.around(airport.geometry)
    area_km2 = frame.geom_to_local(airport.geometry).area / 1e6
    assert 3.0 < area_km2 < 6.0  # Malta International covers about 4 km²


def test_bbox_selects_and_an_empty_selection_is_an_error(malta, rules):
    sub = read_database([malta], rules, bbox=(14.46, 35.83, 14.50, 35.87))
    assert 0 < len(sub.features) < 60
    with pytest.raises(InputError) as err:
        read_database([malta], rules, bbox=(13.0, 35.0, 13.1, 35.1))  # open sea
    assert "no restricted features inside the bounding box 13,35,13.1,35.1" in str(err.value)
    assert str(malta) in str(err.value)


def test_truncated_pbf_is_a_one_line_error(malta, rules, tmp_path):
    cut = tmp_path / "cut.osm.pbf"
    cut.write_bytes(malta.read_bytes()[:200_000])
    with pytest.raises(InputError) as err:
        read_database([cut], rules)
    msg = str(err.value)
    assert msg.startswith(str(cut)) and "\n" not in msg


def test_osm_xml(tmp_path, rules):
    xml = tmp_path / "tiny.osm"
    xml.write_text(
        """<?xml version='1.0' encoding='UTF-8'?>
<osm version="0.6">
 <node id="1" lat="35.0" lon="14.0"/><node id="2" lat="35.0" lon="14.001"/>
 <node id="3" lat="35.001" lon="14.001"/><node id="4" lat="35.001" lon="14.0"/>
 <node id="5" lat="35.01" lon="14.01"><tag k="amenity" v="hospital"/><tag k="name" v="Node Hospital"/></node>
 <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="4"/><nd ref="1"/>
  <tag k="amenity" v="prison"/><tag k="name" v="Way Prison"/></way>
</osm>"""
    )
    db = read_database([xml], rules)
    got = {f.source: (f.category, f.geomtype) for f in db.features}
    assert got == {"way/10": ("prison", "area"), "node/5": ("hospital", "point")}


QGIS_DOC = {
    "type": "FeatureCollection",
    "name": "multipolygons",
    "features": [
        {
            "type": "Feature",
            "properties": {
                "osm_id": "533025",
                "osm_way_id": None,
                "name": "Canada Copse",
                "landuse": "forest",
                "aeroway": None,
                "amenity": None,
            },
            "geometry": {
                "type": "MultiPolygon",
                "coordinates": [
                    [[[-0.55, 51.43], [-0.549, 51.43], [-0.549, 51.431], [-0.55, 51.43]]]
                ],
            },
        },
        {
            "type": "Feature",
            "properties": {
                "osm_id": None,
                "osm_way_id": "777",
                "name": "Example Hospital",
                "landuse": None,
                "aeroway": None,
                "amenity": "hospital",
            },
            "geometry": {
                "type": "MultiPolygon",
                "coordinates": [
                    [
                        [
                            [-0.54, 51.43],
                            [-0.539, 51.43],
                            [-0.539, 51.431],
                            [-0.54, 51.431],
                            [-0.54, 51.43],
                        ]
                    ]
                ],
            },
        },
        {
            "type": "Feature",
            "properties": {
                "osm_id": "99",
                "osm_way_id": None,
                "name": "Heli",
                "aeroway": None,
                "other_tags": '"aeroway"=>"helipad","surface"=>"grass"',
            },
            "geometry": {"type": "Point", "coordinates": [-0.53, 51.43]},
        },
    ],
}


def test_qgis_geojson_with_null_tag_columns_and_other_tags(write_json, rules):
    db = read_database([write_json("qgis.geojson", QGIS_DOC)], rules)
    got = {f.source: f for f in db.features}
    assert set(got) == {"way/777", "node/99"}  # the forest is not restricted
    assert got["way/777"].category == "hospital" and "landuse" not in got["way/777"].tags
    assert got["node/99"].category == "aerodrome" and got["node/99"].tags["surface"] == "grass"


def test_hstore():
    assert parse_hstore('"a"=>"1","b c"=>"x \\"q\\"","n"=>NULL') == {"a": "1", "b c": 'x "q"'}
    assert tags_of({"osm_id": "1", "x": None, "flag": True, "n": 3}) == {"flag": "yes", "n": "3"}


ED269 = {
    "title": "test zones",
    "features": [
        {
            "identifier": "EX-P1",
            "country": "XXX",
            "name": "Prohibited square",
            "type": "COMMON",
            "restriction": "PROHIBITED",
            "reason": ["SENSITIVE"],
            "applicability": [
                {
                    "permanent": "NO",
                    "startDateTime": "2026-11-01T00:00:00Z",
                    "endDateTime": "2026-12-01T00:00:00Z",
                }
            ],
            "geometry": [
                {
                    "uomDimensions": "FT",
                    "lowerLimit": 0,
                    "lowerVerticalReference": "AGL",
                    "upperLimit": 400,
                    "upperVerticalReference": "AGL",
                    "horizontalProjection": {
                        "type": "Polygon",
                        "coordinates": [
                            [
                                [14.0, 35.0],
                                [14.01, 35.0],
                                [14.01, 35.01],
                                [14.0, 35.01],
                                [14.0, 35.0],
                            ]
                        ],
                    },
                }
            ],
        },
        {
            "identifier": "EX-C1",
            "country": "XXX",
            "name": "Conditional circle",
            "type": "COMMON",
            "restriction": "CONDITIONAL",
            "reason": ["AIR_TRAFFIC"],
            "geometry": [
                {
                    "uomDimensions": "M",
                    "lowerLimit": 30,
                    "lowerVerticalReference": "AMSL",
                    "upperLimit": 150,
                    "upperVerticalReference": "AMSL",
                    "horizontalProjection": {
                        "type": "Circle",
                        "center": [14.1, 35.1],
                        "radius": 500,
                    },
                }
            ],
        },
        {
            "identifier": "EX-N1",
            "restriction": "NO_RESTRICTION",
            "geometry": [
                {"horizontalProjection": {"type": "Circle", "center": [14.2, 35.2], "radius": 100}}
            ],
        },
    ],
}


def test_ed269_polygon_and_circle(write_json, rules):
    db = read_database([write_json("zones.json", ED269)], rules)
    got = {f.source: f for f in db.features}
    assert set(got) == {"EX-P1", "EX-C1"}
    p1, c1 = got["EX-P1"], got["EX-C1"]
    assert p1.kind == "keep_out" and c1.kind == "warning"
    assert p1.alt_min_m == 0 and p1.alt_max_m == pytest.approx(400 * 0.3048)
    assert c1.alt_min_m == 30 and c1.alt_max_m == 150 and c1.properties["lower_reference"] == "AMSL"
    assert p1.properties["applicability"][0]["permanent"] == "NO"
    # the circle polygon contains the 500 m circle, and not much more
    frame = LocalFrame(14.1, 35.1)
    local = frame.geom_to_local(c1.geometry)
    assert local.covers(shapely.Point(0, 0).buffer(499.99, quad_segs=64))
    assert local.area < 3.1416 * 505**2


@pytest.mark.parametrize(
    "doc, expected",
    [
        (
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"amenity": "prison"},
                        "geometry": {"type": "Curve", "coordinates": []},
                    }
                ],
            },
            "feature 0: unknown geometry type 'Curve'",
        ),
        (
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"amenity": "prison", "osm_way_id": "5"},
                        "geometry": {"type": "Point", "coordinates": [200.5, 35.0]},
                    }
                ],
            },
            "way/5: coordinate (200.5, 35.0) out of range",
        ),
        (
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"amenity": "prison"},
                        "geometry": {"type": "Polygon", "coordinates": [[[1, 2]]]},
                    }
                ],
            },
            "feature 0: malformed Polygon geometry",
        ),
        (
            {
                "type": "FeatureCollection",
                "features": [
                    {"type": "Feature", "properties": {"amenity": "school"}, "geometry": None}
                ],
            },
            "no restricted features",
        ),
        (
            {
                "features": [
                    {
                        "identifier": "Z1",
                        "restriction": "PROHIBITED",
                        "geometry": [
                            {
                                "horizontalProjection": {
                                    "type": "Circle",
                                    "center": [14.0, 35.0],
                                    "radius": -5,
                                }
                            }
                        ],
                    }
                ]
            },
            "zone Z1: Circle radius must be a positive number",
        ),
        (
            {
                "features": [
                    {
                        "identifier": "Z2",
                        "restriction": "PROHIBITED",
                        "geometry": [
                            {
                                "uomDimensions": "M",
                                "lowerLimit": 100,
                                "upperLimit": 50,
                                "horizontalProjection": {
                                    "type": "Circle",
                                    "center": [14.0, 35.0],
                                    "radius": 5,
                                },
                            }
                        ],
                    }
                ]
            },
            "zone Z2: upperLimit 50.0 m is not above lowerLimit 100.0 m",
        ),
    ],
)
def test_bad_input_is_a_one_line_error_naming_file_and_feature(write_json, rules, doc, expected):
    path = write_json("bad.json", doc)
    with pytest.raises(InputError) as err:
        read_database([path], rules)
    msg = str(err.value)
    assert msg.startswith(str(path)) and expected in msg and "\n" not in msg


def test_malformed_json_and_unknown_format(tmp_path, rules):
    bad = tmp_path / "broken.geojson"
    bad.write_text('{"type": "FeatureCollection", "features": [')
    with pytest.raises(InputError, match=r"broken.geojson: malformed JSON at line 1"):
        read_database([bad], rules)
    other = tmp_path / "fences.csv"
    other.write_text("a,b\n")
    with pytest.raises(InputError, match="unknown database format"):
        read_database([other], rules)
    with pytest.raises(InputError, match="no such file"):
        read_database([tmp_path / "missing.osm.pbf"], rules)


def test_self_intersecting_polygon_is_reported_and_repaired(write_json, rules):
    bowtie = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"amenity": "prison", "osm_way_id": "8"},
                "geometry": {
                    "type": "Polygon",
                    "coordinates": [
                        [
                            [14.0, 35.0],
                            [14.001, 35.001],
                            [14.001, 35.0],
                            [14.0, 35.001],
                            [14.0, 35.0],
                        ]
                    ],
                },
            }
        ],
    }
    db = read_database([write_json("bowtie.geojson", bowtie)], rules)
    assert db.repaired == ["way/8"]
    from alphafence.fencing.pipeline import build_fences

    result = build_fences(db.features, rules)
    site = result.sites[0]
    assert site.geometry.is_valid and site.geometry.area > 0.4 * 90 * 111 * 0.5


def test_demo_scene_ships_with_the_package(rules):
    from alphafence.cli.demo import scene_path

    assert shutil.os.path.isfile(scene_path())
    db = read_database([scene_path()], rules)
    assert {f.category for f in db.features} >= {
        "aerodrome",
        "hospital",
        "prison",
        "school",
        "power",
        "military",
    }


def test_oversized_json_is_refused_before_reading(write_json, rules, monkeypatch):
    path = write_json("big.json", ED269)
    monkeypatch.setenv("ALPHAFENCE_MAX_JSON_MB", "0.0001")  # about 100 bytes
    with pytest.raises(InputError, match=r"more than the 0 MB limit .*ALPHAFENCE_MAX_JSON_MB"):
        read_database([path], rules)
    monkeypatch.delenv("ALPHAFENCE_MAX_JSON_MB")
    assert read_database([path], rules).features


def test_geojson_above_the_json_limit_is_streamed(write_json, rules, monkeypatch):
    path = write_json("big.geojson", QGIS_DOC)
    whole = read_database([path], rules).features
    monkeypatch.setenv("ALPHAFENCE_MAX_JSON_MB", "0.0001")  # read whole, it would be refused
    streamed = read_database([path], rules).features
    assert [f.source for f in streamed] == [f.source for f in whole]
    assert all(a.geometry.equals_exact(b.geometry, 0) for a, b in zip(streamed, whole))
