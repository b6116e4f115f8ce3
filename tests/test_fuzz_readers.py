"""Readers fed malformed input: only clean one-line InputErrors, never another exception.

`make test` runs a small sample; `make fuzz` runs many more (ALPHAFENCE_FUZZ_EXAMPLES)."""

import json
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError, InputErrors
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.qgc_plan import read_plan_fence, read_plan_geofence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
from alphafence.flights.mission import read_mission
from alphafence.zones.database import read_database
from alphafence.zones.rules import load_rules

N = int(os.environ.get("ALPHAFENCE_FUZZ_EXAMPLES", "60"))
FUZZ = settings(max_examples=N, deadline=None, suppress_health_check=list(HealthCheck))
RULES = load_rules()

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
json_values = st.recursive(
    scalars,
    lambda kids: st.one_of(
        st.lists(kids, max_size=5), st.dictionaries(st.text(max_size=8), kids, max_size=5)
    ),
    max_leaves=30,
)
coords = st.lists(
    st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-1000, 1000), scalars),
    min_size=0,
    max_size=3,
)
rings = st.lists(coords, max_size=6)
geometry = st.one_of(
    st.fixed_dictionaries(
        {
            "type": st.sampled_from(
                ["Point", "LineString", "Polygon", "MultiPolygon", "Curve", "GeometryCollection"]
            ),
            "coordinates": st.one_of(coords, rings, st.lists(rings, max_size=3), json_values),
        }
    ),
    json_values,
)
feature = st.fixed_dictionaries(
    {
        "type": st.sampled_from(["Feature", "Feature", "Nope"]),
        "properties": st.one_of(
            st.dictionaries(
                st.sampled_from(
                    [
                        "amenity",
                        "aeroway",
                        "name",
                        "osm_id",
                        "osm_way_id",
                        "other_tags",
                        "landuse",
                        "kind",
                        "site_id",
                    ]
                ),
                st.one_of(st.sampled_from(["hospital", "prison", "keep_out", "helipad"]), scalars),
                max_size=4,
            ),
            json_values,
        ),
        "geometry": geometry,
    }
)


def write(suffix, data):
    fd, path = tempfile.mkstemp(suffix=suffix)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data if isinstance(data, bytes) else data.encode("utf-8", "surrogatepass"))
    return Path(path)


def only_input_errors(fn, path):
    try:
        fn(path)
    except InputErrors as exc:  # every fault of a file at once: a count, then one line each
        assert len(str(exc).splitlines()) == 1 + len(exc.errors) and len(exc.errors) > 1
        assert all("\n" not in str(e) and str(e) for e in exc.errors)
    except InputError as exc:
        assert "\n" not in str(exc) and str(exc)
    finally:
        path.unlink(missing_ok=True)


@FUZZ
@given(
    st.one_of(
        st.fixed_dictionaries(
            {"type": st.just("FeatureCollection"), "features": st.lists(feature, max_size=4)}
        ),
        json_values,
    )
)
def test_geojson_reader(doc):
    only_input_errors(lambda p: read_database([p], RULES), write(".geojson", json.dumps(doc)))


# limits and radii as files write them: numbers, numeric strings, and strings that are not
limits = st.one_of(
    scalars, st.sampled_from(["0", "120", " 50 ", "-5", "1e400", "nan", "inf", "ten", ""])
)
zone = st.fixed_dictionaries(
    {
        "identifier": st.one_of(st.text(max_size=6), scalars),
        "restriction": st.one_of(
            st.sampled_from(["PROHIBITED", "CONDITIONAL", "REQ_AUTHORISATION"]), scalars
        ),
        "geometry": st.one_of(
            st.lists(
                st.fixed_dictionaries(
                    {
                        "uomDimensions": st.one_of(st.sampled_from(["M", "FT"]), scalars),
                        "lowerLimit": limits,
                        "upperLimit": limits,
                        "horizontalProjection": st.one_of(
                            st.fixed_dictionaries(
                                {"type": st.just("Circle"), "center": coords, "radius": limits}
                            ),
                            st.fixed_dictionaries(
                                {
                                    "type": st.sampled_from(["Polygon", "Spline"]),
                                    "coordinates": st.lists(rings, max_size=2),
                                }
                            ),
                            json_values,
                        ),
                    }
                ),
                max_size=3,
            ),
            json_values,
        ),
    }
)


# ED-318: GeoJSON features whose geometries carry a vertical layer
layer = st.one_of(
    st.fixed_dictionaries(
        {
            "upper": limits,
            "lower": limits,
            "uom": st.one_of(st.sampled_from(["m", "ft", "FT"]), scalars),
            "upperReference": st.one_of(st.sampled_from(["AGL", "AMSL", "WGS84"]), scalars),
            "lowerReference": st.one_of(st.sampled_from(["AGL", "AMSL", "WGS84"]), scalars),
        }
    ),
    json_values,
)
ed318_part = st.one_of(
    st.fixed_dictionaries(
        {
            "type": st.just("Point"),
            "coordinates": coords,
            "extent": st.one_of(
                st.fixed_dictionaries({"subType": st.just("Circle"), "radius": limits}),
                json_values,
            ),
            "layer": layer,
        }
    ),
    st.fixed_dictionaries(
        {
            "type": st.sampled_from(["Polygon", "MultiPolygon", "LineString", "Curve"]),
            "coordinates": st.one_of(st.lists(rings, max_size=2), json_values),
            "layer": layer,
        }
    ),
    json_values,
)
ed318_feature = st.fixed_dictionaries(
    {
        "type": st.just("Feature"),
        "properties": st.one_of(
            st.fixed_dictionaries(
                {
                    "identifier": st.one_of(st.text(max_size=7), scalars),
                    "type": st.one_of(
                        st.sampled_from(["PROHIBITED", "REQ_AUTHORIZATION", "USPACE"]), scalars
                    ),
                    "name": json_values,
                    "reasons": json_values,
                    "zoneAuthority": json_values,
                    "limitedApplicability": json_values,
                }
            ),
            st.fixed_dictionaries({"UASZone": json_values, "verticalLayer": layer}),
            json_values,
        ),
        "geometry": st.one_of(
            ed318_part,
            st.fixed_dictionaries(
                {
                    "type": st.just("GeometryCollection"),
                    "geometries": st.one_of(st.lists(ed318_part, max_size=3), json_values),
                }
            ),
        ),
    }
)
ED269_SAMPLES = sorted((Path(__file__).parent / "data" / "ed269").glob("*.json"))


@FUZZ
@given(
    st.one_of(
        st.fixed_dictionaries({"features": st.lists(zone, min_size=1, max_size=3)}),
        st.fixed_dictionaries(
            {"formatVersion": st.just("1.0.0"), "UASZoneList": st.lists(zone, max_size=3)}
        ),
        st.lists(zone, min_size=1, max_size=3),
        st.fixed_dictionaries(
            {
                "type": st.just("FeatureCollection"),
                "features": st.lists(ed318_feature, min_size=1, max_size=3),
            }
        ),
    )
)
def test_ed269_reader(doc):
    only_input_errors(lambda p: read_database([p], RULES), write(".json", json.dumps(doc)))


@pytest.mark.parametrize("sample", ED269_SAMPLES, ids=lambda p: p.name)
@FUZZ
@given(data=st.data())
def test_ed269_reader_on_samples_with_one_value_changed(sample, data):
    """The samples (ED-269 in both wrappers, ED-318) with one value replaced by anything."""
    doc = json.loads(sample.read_text())
    node, parent, key = doc, None, None
    for _ in range(8):  # walk down towards a leaf, then replace what the walk stopped at
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        if not keys:
            break
        parent, key = node, data.draw(st.sampled_from(keys))
        node = node[key]
        if not isinstance(node, (dict, list)) or data.draw(st.booleans()):
            break
    if parent is not None:
        parent[key] = data.draw(json_values)
    only_input_errors(lambda p: read_database([p], RULES), write(".json", json.dumps(doc)))


@FUZZ
@given(
    st.one_of(
        json_values,
        st.fixed_dictionaries(
            {"type": st.just("FeatureCollection"), "features": st.lists(feature, max_size=4)}
        ),
    )
)
def test_fence_geojson_reader(doc):
    only_input_errors(read_fences, write(".geojson", json.dumps(doc)))


@FUZZ
@given(
    st.one_of(
        json_values,
        st.fixed_dictionaries(
            {
                "geoFence": st.fixed_dictionaries(
                    {
                        "polygons": st.lists(
                            st.fixed_dictionaries(
                                {"inclusion": scalars, "polygon": st.lists(coords, max_size=5)}
                            ),
                            max_size=3,
                        ),
                        "circles": st.lists(
                            st.fixed_dictionaries({"inclusion": scalars, "circle": json_values}),
                            max_size=2,
                        ),
                    }
                )
            }
        ),
    )
)
def test_plan_reader(doc):
    only_input_errors(read_plan_fence, write(".plan", json.dumps(doc)))


@FUZZ
@given(
    st.one_of(st.sampled_from([1, 2, 3]), st.none(), scalars),
    st.one_of(st.lists(coords, max_size=5), json_values),
    st.one_of(coords, st.none(), scalars),
)
def test_plan_reader_version_1(version, polygon, breach_return):
    # QGroundControl 3.2's geoFence: one "polygon" and a breachReturn without an altitude
    fence = {"version": version, "polygon": polygon, "breachReturn": breach_return}
    doc = {"fileType": "Plan", "geoFence": {k: v for k, v in fence.items() if v is not None}}
    only_input_errors(read_plan_geofence, write(".plan", json.dumps(doc)))


def test_a_version_2_geofence_without_polygons_or_circles_is_empty(tmp_path):
    # found by test_plan_reader_version_1: a KeyError, where the lists default to none
    path = tmp_path / "empty.plan"
    path.write_text(json.dumps({"fileType": "Plan", "geoFence": {"version": 2}}))
    fence = read_plan_geofence(path)
    assert fence.items == [] and fence.return_point is None


param_values = st.one_of(st.floats(-200, 200), st.integers(-2, 8), scalars)
plan_items = st.lists(
    st.fixed_dictionaries(
        {
            "type": st.sampled_from(["SimpleItem", "missionItem", "ComplexItem"]),
            "command": st.one_of(st.sampled_from([16, 20, 22, 36, 80, 94, 177, 600, 601]), scalars),
            "doJumpId": st.one_of(st.integers(0, 8), scalars),
            "params": st.one_of(st.lists(param_values, max_size=8), scalars),
        },
        optional={
            "coordinate": coords,
            "param1": param_values,
            "param2": param_values,
            "param3": scalars,
            "param4": scalars,
            "TransectStyleComplexItem": json_values,
        },
    ),
    max_size=8,
)


@FUZZ
@given(plan_items, st.one_of(coords, json_values))
def test_plan_mission_reader(items, home):
    # every item form QGroundControl reads, DO_JUMPs by doJumpId to anywhere, loops for ever
    doc = {"mission": {"items": items, "plannedHomePosition": home}}
    only_input_errors(lambda p: read_mission(p, 1), write(".plan", json.dumps(doc)))


@FUZZ
@given(
    st.lists(
        st.tuples(
            st.integers(0, 9),
            st.sampled_from(["16", "20", "22", "94", "177", "600", "601", "5000", "x"]),
            st.sampled_from(["0", "1", "2", "-1", "3.5", "nan", "1e12"]),
            st.sampled_from(["0", "2", "-1", "nan", "inf", "5"]),
            st.sampled_from(["35.9", "0", "nan", "95", "-35.9"]),
            st.sampled_from(["14.5", "0", "200", "-14.5"]),
        ),
        max_size=8,
    )
)
def test_waypoints_mission_reader(rows):
    lines = ["QGC WPL 110"] + [
        "\t".join([str(seq), "0", "3", cmd, p1, p2, "0", "0", lat, lon, "30", "1"])
        for seq, cmd, p1, p2, lat, lon in rows
    ]
    only_input_errors(lambda p: read_mission(p, 1), write(".waypoints", "\n".join(lines) + "\n"))


@FUZZ
@given(
    st.lists(
        st.lists(
            st.one_of(
                st.sampled_from(["0", "1", "5002", "5004", "3.5", "nan", "inf", "200", "-95"]),
                st.text(max_size=4),
            ),
            max_size=13,
        ),
        max_size=6,
    ),
    st.sampled_from(["QGC WPL 110", "QGC WPL 120", "garbage"]),
)
def test_waypoints_reader(rows, header):
    text = "\n".join([header] + ["\t".join(r) for r in rows]) + "\n"
    only_input_errors(read_waypoints_fence, write(".waypoints", text))


@FUZZ
@given(st.binary(max_size=400), st.sampled_from([".osm.pbf", ".osm"]))
def test_osm_reader_on_garbage(data, suffix):
    only_input_errors(lambda p: read_database([p], RULES), write(suffix, data))


@FUZZ
@given(st.one_of(st.text(max_size=300), st.binary(max_size=300)))
def test_rules_reader(text):  # bytes: not always UTF-8 (found by tests/atheris_fuzz.py)
    only_input_errors(load_rules, write(".toml", text))


def test_truncated_pbf_at_many_lengths(tmp_path):
    from tests.conftest import MONACO

    if not MONACO.is_file():
        pytest.skip("Monaco extract not found")
    data = MONACO.read_bytes()
    for cut in (0, 1, 17, 100, 4096, 65_537, len(data) // 3, len(data) - 1):
        only_input_errors(lambda p: read_database([p], RULES), write(".osm.pbf", data[:cut]))


# -- KML/KMZ, OpenAir, ArduPilot's legacy fences; fence files as fences -------------------

openair_args = st.one_of(
    st.sampled_from(
        [
            "R",
            "SFC",
            "GND",
            "FL65",
            "FL 999",
            "1000ft AGL",
            "UNL",
            "-5m",
            "600 m MSL",
            "1e400",
            "X=52:00:00 N 001:00:00 W",
            "X=52:00.5N 001:00.5E",
            "X=99:00:00 N 200:00:00 E",
            "D=-",
            "D=+",
            "D=?",
            "W=5",
            "52:00:00 N 001:00:00 W",
            "52:10:00N 001:10:00E",
            "52:00:00 N 001:00:00 W, 52:01:00 N 001:00:00 W",
            "52:00:61 N 001:00:00 W",
            "2,0,90",
            "2, 90, 0",
            "0.5",
            "0",
            "-1",
            "nan",
            "1e12",
            "5,0,360",
            "1e12,0,180",
        ]
    ),
    st.text(max_size=12),
)
openair_records = st.lists(
    st.tuples(
        st.sampled_from(
            ["AC", "AN", "AY", "AL", "AH", "V", "DP", "DA", "DB", "DC", "DY", "SP", "AT", "*"]
        ),
        openair_args,
    ),
    max_size=14,
)


@FUZZ
@given(openair_records, st.sampled_from([".openair", ".txt"]))
def test_openair_reader(records, suffix):
    from alphafence.fencefiles.fence_read import read_fence_file

    text = "AC R\n" + "".join(f"{cmd} {arg}\n" for cmd, arg in records)
    for read in (lambda p: read_database([p], RULES), read_fence_file):
        only_input_errors(read, write(suffix, text))


def _xml_text(value):
    return str(value).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


kml_tuples = st.lists(
    st.lists(
        st.one_of(st.floats(-200, 200), st.integers(-1000, 1000), st.sampled_from(["nan", "x"])),
        min_size=1,
        max_size=4,
    ).map(lambda t: ",".join(map(str, t))),
    max_size=6,
).map(" ".join)
kml_common = st.tuples(
    st.sampled_from(["", "absolute", "relativeToGround", "clampToGround", "relativeToSeaFloor"]),
    st.sampled_from(["", "0", "1", "true"]),
)


def _kml_geometry(kind, coords, mode, extrude, inner=""):
    head = f"<altitudeMode>{mode}</altitudeMode><extrude>{extrude}</extrude>"
    ring = f"<LinearRing><coordinates>{coords}</coordinates></LinearRing>"
    if kind == "Polygon":
        body = f"<outerBoundaryIs>{ring}</outerBoundaryIs>{inner}"
    elif kind == "LinearRing":
        body = f"<coordinates>{coords}</coordinates>"
    elif kind == "Empty":
        return "<Polygon/>"
    else:
        body = f"<coordinates>{coords}</coordinates>"
    return f"<{kind}>{head}{body}</{kind}>"


kml_geometry = st.builds(
    _kml_geometry,
    st.sampled_from(["Point", "LineString", "LinearRing", "Polygon", "Empty", "Model"]),
    kml_tuples,
    *[st.sampled_from(v) for v in (["", "absolute", "relativeToGround"], ["0", "1"])],
    st.sampled_from(
        [
            "",
            "<innerBoundaryIs><LinearRing><coordinates>1,1 2,2</coordinates>"
            "</LinearRing></innerBoundaryIs>",
        ]
    ),
)
kml_placemark = st.builds(
    lambda name, data, geoms, multi: (
        f"<Placemark><name>{_xml_text(name)}</name><ExtendedData>"
        + "".join(f'<Data name="{k}"><value>{_xml_text(v)}</value></Data>' for k, v in data)
        + "</ExtendedData>"
        + (f"<MultiGeometry>{''.join(geoms)}</MultiGeometry>" if multi else "".join(geoms[:1]))
        + "</Placemark>"
    ),
    st.text(max_size=6),
    st.lists(
        st.tuples(
            st.sampled_from(["radius", "alphafence:kind", "class"]),
            st.one_of(
                st.sampled_from(["150", "-1", "nan", "keep_in", "bogus", "1e400"]),
                st.text(max_size=4),
            ),
        ),
        max_size=2,
    ),
    st.lists(kml_geometry, max_size=3),
    st.booleans(),
)


@FUZZ
@given(
    st.one_of(
        st.lists(kml_placemark, max_size=4).map(
            lambda pms: (
                '<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2">'
                f"<Document><Folder><name>f</name>{''.join(pms)}</Folder></Document></kml>"
            )
        ),
        st.binary(max_size=300),
    ),
    st.sampled_from([".kml", ".kmz"]),
)
def test_kml_reader(doc, suffix):
    import io
    import zipfile

    from alphafence.fencefiles.fence_read import read_fence_file

    data = doc.encode("utf-8", "surrogatepass") if isinstance(doc, str) else doc
    if suffix == ".kmz" and isinstance(doc, str):
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("doc.kml", data)
        data = buf.getvalue()
    for read in (lambda p: read_database([p], RULES), read_fence_file):
        only_input_errors(read, write(suffix, data))


fence_item_rows = st.lists(
    st.tuples(
        st.sampled_from(["5000", "5001", "5002", "5003", "5004"]),
        st.sampled_from(["0", "3", "4", "2.5", "nan", "-1", "80", "1e400"]),
        st.sampled_from(["-35.36", "-35.35", "nan", "95"]),
        st.sampled_from(["149.16", "149.17", "200"]),
    ),
    max_size=9,
)


@FUZZ
@given(
    st.lists(
        st.lists(
            st.one_of(
                st.sampled_from(["-35.36", "149.16", "-35.35", "149.17", "nan", "95", "# c"]),
                st.text(max_size=5),
            ),
            max_size=3,
        ).map(" ".join),
        max_size=8,
    ),
    st.booleans(),
    fence_item_rows,
)
def test_legacy_fence_and_fence_items_as_fences(lines, close, rows):
    """ArduPilot's legacy fence files, and fence .waypoints files read as fences (their
    polygon counts must be checked: a count of 0 would never advance)."""
    from alphafence.fencefiles.fence_read import read_fence_file

    if close and len(lines) > 1:
        lines = lines + [lines[1]]
    only_input_errors(read_fence_file, write(".txt", "\n".join(lines) + "\n"))
    wpl = ["QGC WPL 110"] + [
        "\t".join([str(k), "0", "0", cmd, p1, "0", "0", "0", lat, lon, "0", "1"])
        for k, (cmd, p1, lat, lon) in enumerate(rows)
    ]
    only_input_errors(read_fence_file, write(".waypoints", "\n".join(wpl) + "\n"))


def _flight_logs():
    """A small valid .tlog and .BIN (a flight through a fence), and that fence."""
    from tests.test_check_flight import WALL, feature, track, write_bin, write_tlog

    d = Path(tempfile.mkdtemp())
    tr = track([(0, 150), (0, 300)], rate=2.0)
    logs = {".tlog": write_tlog(d / "f.tlog", tr).read_bytes()}
    logs[".BIN"] = write_bin(d / "f.BIN", tr).read_bytes()
    fences = d / "fences.geojson"
    fences.write_text(
        json.dumps({"type": "FeatureCollection", "features": [feature("w/1", "keep_out", WALL)]})
    )
    return logs, fences


FLIGHT_LOGS = None
DF_CHARS = "abBhHiIfdnNZcCeELMqQg"


def _checked_flight(path):
    from alphafence.flights.flight_log import FlightLog
    from alphafence.review.postflight import check_flight, load_fences

    json.dumps(
        check_flight(FlightLog(path), load_fences(FLIGHT_LOGS[1])).to_json(), allow_nan=False
    )


def _hostile_fmt(fmt, cols, body):
    """A DataFlash log whose POS has a random declaration and body."""
    import struct

    size = 3 + sum(struct.calcsize(s) for s in (
        {"a": "64s", "n": "4s", "N": "16s", "Z": "64s", "q": "q", "Q": "Q", "d": "d"}.get(c, "i") for c in fmt
    ))  # fmt: skip
    head = b"\xa3\x95\x80" + struct.pack(
        "<BB4s16s64s", 132, size % 256, b"POS", fmt.encode(), cols.encode()
    )
    return head + (b"\xa3\x95\x84" + body.ljust(size, b"\x00")[: max(size - 3, 0)]) * 3


@FUZZ
@given(
    st.sampled_from([".tlog", ".BIN"]),
    st.integers(0, 4000),
    st.lists(st.tuples(st.integers(0, 4000), st.integers(0, 255)), max_size=8),
    st.binary(max_size=40),
    st.tuples(
        st.text(DF_CHARS, max_size=8),
        st.lists(
            st.sampled_from(["TimeUS", "Lat", "Lng", "Alt", "RelHomeAlt", "I", "x"]), max_size=8
        ),
        st.binary(max_size=120),
    ),
)
def test_flight_log_readers_and_the_check(suffix, cut, flips, tail, hostile):
    global FLIGHT_LOGS
    FLIGHT_LOGS = FLIGHT_LOGS or _flight_logs()
    data = bytearray(FLIGHT_LOGS[0][suffix][:cut])
    for at, byte in flips:
        if at < len(data):
            data[at] = byte
    only_input_errors(_checked_flight, write(suffix, bytes(data) + tail))
    fmt, cols, body = hostile
    only_input_errors(_checked_flight, write(".BIN", _hostile_fmt(fmt, ",".join(cols), body)))
