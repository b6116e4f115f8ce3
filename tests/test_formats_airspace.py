"""KML/KMZ and OpenAir zones as restricted-feature databases, each checked against an
independent parse of the same file (xml.etree for KML, a regular expression and pyproj's
geodesics for OpenAir's positions and arcs)."""

import re
import xml.etree.ElementTree as ET
import zipfile
from collections import Counter
from pathlib import Path

import pytest
import shapely
from pyproj import Geod

from alphafence.errors import InputError
from alphafence.geo.frame import LocalFrame
from alphafence.zones import kml, openair_alt
from alphafence.zones.database import read_database
from alphafence.zones.rules import parse_rules
from tests.test_kml_great_circles import FOLLOW_M, assert_held_both_ways

DATA = Path(__file__).parent / "data"
OPENAIR = DATA / "openair" / "sample.openair"
UK3D = DATA / "kml" / "uk-3d-zones.kml"
EARTH = DATA / "kml" / "google-earth.kml"
GEOD = Geod(ellps="WGS84")
NS = {"k": "http://www.opengis.net/kml/2.2"}


def kmz(tmp_path, source, arcname="eaip3d-test.kml"):
    """A KMZ of ``source`` as a national export packs it: one .kml, not named doc.kml."""
    path = tmp_path / (source.stem + ".kmz")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(source, arcname)
    return path


def by_name(features):
    return {f.name: f for f in features}


# -- OpenAir -----------------------------------------------------------------------------


def dms(text):
    """Independent DMS parse: '52:20:00 N' -> 52.333..., west and south negative."""
    d, m, s, h = re.fullmatch(r"(\d+):(\d+):(\d+)\s*([NSEW])", text.strip()).groups()
    value = int(d) + int(m) / 60 + int(s) / 3600
    return -value if h in "SW" else value


def openair_blocks():
    """The sample's airspaces as lists of (command, argument), split at AC."""
    blocks = []
    for line in OPENAIR.read_text().splitlines():
        if not line.strip() or line.startswith("*"):
            continue
        cmd, _, arg = line.partition(" ")
        if cmd == "AC":
            blocks.append([])
        blocks[-1].append((cmd, arg))
    return blocks


def position(arg):
    lat, lon = re.findall(r"\d+:\d+:\d+\s*[NSEW]", arg)
    return dms(lon), dms(lat)


def test_openair_airspaces_become_keep_out_features_with_their_bands(rules):
    db = read_database([OPENAIR], rules)
    got = by_name(db.features)
    assert len(db.features) == 6 and {f.kind for f in db.features} == {"keep_out"}
    assert {f.category for f in db.features} == {"airspace"}
    r = got["EGR999 TEST RANGE"]
    assert (r.alt_min_m, r.alt_max_m) == (0.0, pytest.approx(2000 * 0.3048))
    assert r.properties["lower_reference"] == "AGL" and r.properties["upper_reference"] == "AMSL"
    assert r.tags["airspace:class"] == "R" and r.tags["airspace:format"] == "openair"
    p = got["EGP998 PRISON"]  # FL65: pressure altitude, kept as such
    assert p.alt_max_m == pytest.approx(6500 * 0.3048) and p.properties["upper_reference"] == "STD"
    ctr = got["WELLESBOURNE CTR"]
    assert (ctr.alt_min_m, ctr.alt_max_m) == (pytest.approx(457.2), pytest.approx(1066.8))
    assert ctr.tags["airspace:type"] == "CTR" and ctr.properties["lower_reference"] == "AGL"
    assert got["DANGER SECTOR"].alt_min_m == 150 and got["DANGER SECTOR"].alt_max_m == 600
    assert got["NOTCHED AREA (concave arc)"].alt_max_m is None  # UNL
    wave = got["WAVE BOX"]
    assert (wave.alt_min_m, wave.alt_max_m) == (pytest.approx(3048.0), pytest.approx(5943.6))


def test_openair_polygon_points_equal_an_independent_parse(rules):
    (block, *_), features = openair_blocks(), read_database([OPENAIR], rules).features
    expected = [position(arg) for cmd, arg in block if cmd == "DP"]
    got = list(features[0].geometry.exterior.coords)
    assert [c for p in got for c in p] == pytest.approx([c for p in expected for c in p], abs=1e-12)
    assert len(got) == 5  # closed as written: no point added or lost


def true_arc(centre, start_az, end_az, radius_m, clockwise, step=0.1):
    """Geodesic points of the arc (pyproj, not the kit's frames)."""
    sweep = ((end_az - start_az) if clockwise else (start_az - end_az)) % 360 or 360
    n = int(sweep / step) + 1
    azimuths = [start_az + (k * sweep / n if clockwise else -k * sweep / n) for k in range(n + 1)]
    lons, lats, _ = GEOD.fwd(
        [centre[0]] * len(azimuths),
        [centre[1]] * len(azimuths),
        azimuths,
        [radius_m] * len(azimuths),
    )
    return shapely.points(list(zip(lons, lats)))


def az_dist(centre, point):
    az, _, dist = GEOD.inv(centre[0], centre[1], point[0], point[1])
    return az, dist


def test_openair_circles_and_arcs_lie_inside_their_polygons(rules):
    """Every point of every true arc is covered: arcs are drawn outward, never cutting in."""
    blocks = {dict(b)["AN"]: b for b in openair_blocks()}
    got = by_name(read_database([OPENAIR], rules).features)

    def centre(name):
        return position(next(a for c, a in blocks[name] if c == "V" and a.startswith("X=")))

    def covered(name, arc):
        poly = got[name].geometry
        assert poly.is_valid
        missed = arc[~shapely.dwithin(poly, arc, 1e-9)]  # an end computed apart: 0.1 mm
        assert missed.size == 0, f"{name}: {missed.size} arc points outside, e.g. {missed[:1]}"

    c = centre("EGP998 PRISON")
    covered("EGP998 PRISON", true_arc(c, 0, 360, 1.5 * 1852, True))
    # and the circle is not much bigger than the true one (tangents, 1 m + 0.5 m out)
    area = LocalFrame(*c).geom_to_local(got["EGP998 PRISON"].geometry).area
    r = 1.5 * 1852
    assert 3.14159 * r**2 < area < 3.14159 * (r + 2.0) ** 2
    assert got["EGP998 PRISON"].properties["circle"] == pytest.approx([*c, r])

    c = centre("DANGER SECTOR")  # V D=-, DA 3,90,0: counter-clockwise from east to north
    covered("DANGER SECTOR", true_arc(c, 90, 0, 3 * 1852, False))

    c = centre("WELLESBOURNE CTR")  # DB, clockwise over the north
    (db,) = [a for cmd, a in blocks["WELLESBOURNE CTR"] if cmd == "DB"]
    start, end = [position(p) for p in db.split(",")]
    (az0, r0), (az1, r1) = az_dist(c, start), az_dist(c, end)
    assert r0 == pytest.approx(r1, rel=1e-3)
    covered("WELLESBOURNE CTR", true_arc(c, az0, az1, min(r0, r1), True))

    # a concave arc (the airspace outside its circle): the chord side, still never cutting in
    name = "NOTCHED AREA (concave arc)"
    c = centre(name)
    (db,) = [a for cmd, a in blocks[name] if cmd == "DB"]
    start, end = [position(p) for p in db.split(",")]
    (az0, r0), (az1, _) = az_dist(c, start), az_dist(c, end)
    arc = true_arc(c, az0, az1, r0, False)
    covered(name, arc)
    # the notch is cut out: the centre of the circle lies outside the airspace
    assert not got[name].geometry.covers(shapely.Point(c))


@pytest.mark.parametrize(
    "text, expected",
    [
        ("SFC", (0.0, "AGL")),
        ("GND", (0.0, "AGL")),
        ("UNL", (None, "AMSL")),
        ("FL65", (1981.2, "STD")),
        ("FL 195", (5943.6, "STD")),
        ("2000ft AMSL", (609.6, "AMSL")),
        ("2000", (609.6, "AMSL")),
        ("1500 ft AGL", (457.2, "AGL")),
        ("1000F GND", (304.8, "AGL")),
        ("600m MSL", (600.0, "AMSL")),
        ("3500 ALT", (1066.8, "AMSL")),
    ],
)
def test_openair_altitudes(text, expected):
    assert openair_alt.parse_altitude("f", "AH", text) == expected


@pytest.mark.parametrize(
    "body, message",
    [
        ("AC R\nAN X\nAH 1000ft\nAL SFC\nDA 2,0,90\n", "DA without a centre"),
        (
            "AC R\nAN X\nDP 52:00:00 N 001:00:00 W\nDP 52:01:00 N 001:00:00 W\n"
            "DP 52:02:00 N 001:00:00 W\n",
            "points lie on one line: not an area",
        ),
        ("AC R\nAN X\nAH 500ft\nAL 1000ft\nV X=52:00:00 N 001:00:00 W\nDC 1\n", "not above AL"),
        ("AC R\nAN X\nAH 500ft\n", "without DP, DA, DB or DC"),
        ("AC R\nDP 52:00:00 N 001:00:00 W\nDP 52:01:00 N\n", "expected 1 lat/lon"),
        ("AC R\nDP 52:00:00 N 001:00:00 W\nDP 52:00:00 N 001:00:00 W\n", "at least 3"),
        ("AC R\nDP 52:61:00 N 001:00:00 W\n", "below 60"),
        ("DP 52:00:00 N 001:00:00 W\n", "before the first AC"),
    ],
)
def test_openair_faults_are_one_line(tmp_path, rules, body, message):
    path = tmp_path / "bad.openair"
    path.write_text(body)
    with pytest.raises(InputError, match=message) as err:
        read_database([path], rules)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_openair_in_a_txt_file_latin1_and_rules_that_map_classes(tmp_path):
    path = tmp_path / "airspace.txt"  # the legacy suffix, in the legacy encoding
    path.write_bytes(OPENAIR.read_bytes().replace(b"TEST RANGE", "TEST RÄNGE".encode("latin-1")))
    rules = parse_rules(
        {
            "rule": [
                {
                    "category": "wave",
                    "kind": "warning",
                    "tags": {"airspace:format": "openair", "airspace:class": ["W"]},
                },
                {
                    "category": "airspace",
                    "kind": "keep_out",
                    "tags": {"airspace:format": "*"},
                    "margin_m": 5.0,
                },
            ]
        }
    )
    got = by_name(read_database([path], rules).features)
    assert got["WAVE BOX"].kind == "warning" and got["WAVE BOX"].category == "wave"
    assert got["EGR999 TEST RÄNGE"].kind == "keep_out"


def test_an_openair_airway_is_counted_not_dropped_in_silence(tmp_path, rules):
    path = tmp_path / "airway.openair"
    path.write_text(OPENAIR.read_text() + "\nAC A\nAN AIRWAY\nV W=5\nDY 52:00:00 N 001:00:00 W\n")
    db = read_database([path], rules)
    assert len(db.features) == 6 and db.skipped["OpenAir airway (DY) segments, not read"] == 1


# -- KML / KMZ ---------------------------------------------------------------------------


def etree_placemarks(path):
    """Independent parse: name -> [(lon, lat, alt) rings] of each Placemark's polygons."""
    out = {}
    for pm in ET.parse(path).getroot().iter(f"{{{NS['k']}}}Placemark"):
        name = pm.findtext("k:name", namespaces=NS)
        rings = []
        for coords in pm.iter(f"{{{NS['k']}}}coordinates"):
            rings.append([tuple(map(float, t.split(","))) for t in coords.text.split()])
        out[name] = rings
    return out


def test_a_3d_airspace_export_gives_keep_out_zones_with_their_bands(rules):
    """Floor, ceiling and walls (the UK eAIP 3D layout): the floor's footprint, the band
    from the lowest to the highest altitude, AGL as its altitudeMode says."""
    db = read_database([UK3D], rules)
    got = by_name(db.features)
    truth = etree_placemarks(UK3D)
    assert set(got) == set(truth)
    apart = {}
    for name, rings in truth.items():
        f = got[name]
        written = [(lon, lat) for lon, lat, _ in rings[0]]  # the ceiling
        # held with its edges straight in lon/lat and along geodesics (Google Earth's)
        apart[name] = assert_held_both_ways(f.geometry, [written])
        if apart[name] < FOLLOW_M:  # short edges: as written
            assert list(f.geometry.exterior.coords) == written
        zs = [z for ring in rings for *_, z in ring]
        assert (f.alt_min_m, f.alt_max_m) == (min(zs), max(zs))
        assert f.kind == "keep_out" and f.category == "airspace"
        assert f.properties["lower_reference"] == f.properties["upper_reference"] == "AGL"
        assert f.tags["kml:style"] == "rdpStyleMap"
    assert got["EG R997 TEST RESTRICTED"].alt_min_m == 152.4
    assert got["EG R997 TEST RESTRICTED"].tags["kml:folder"] == "Restricted"
    assert max(apart.values()) > 0.3 and min(apart.values()) < FOLLOW_M  # 4-6 km edges at 52°N


def test_a_kmz_reads_as_its_kml(tmp_path, rules):
    a = read_database([UK3D], rules).features
    b = read_database([kmz(tmp_path, UK3D)], rules).features
    assert [(f.name, f.alt_min_m, f.alt_max_m, f.geometry.wkb) for f in a] == [
        (f.name, f.alt_min_m, f.alt_max_m, f.geometry.wkb) for f in b
    ]


def test_a_kmz_bomb_is_refused_unread(tmp_path, rules, monkeypatch):
    monkeypatch.setenv("ALPHAFENCE_MAX_JSON_MB", "1")
    path = tmp_path / "bomb.kmz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("doc.kml", b"<kml>" + b" " * (20 << 20) + b"</kml>")  # 20 MB in ~20 kB
    assert path.stat().st_size < 100_000
    with pytest.raises(InputError, match="larger than ALPHAFENCE_MAX_JSON_MB"):
        read_database([path], rules)


@pytest.mark.parametrize(
    "data, message",
    [
        (b"PK\x03\x04 not really a zip", "not a readable KMZ"),
        (b"<kml><Document><Placemark>", "malformed XML at line 1"),
        (b"<gpx></gpx>", "not a KML document"),
        (
            b"<kml><Placemark><name>P</name><Point><coordinates>1,2,3,4</coordinates></Point>"
            b"</Placemark></kml>",
            "placemark 0 \\(P\\): malformed coordinates",
        ),
        (
            b"<kml><Placemark><Point><coordinates>500,2</coordinates></Point></Placemark></kml>",
            "out of range",
        ),
        (
            b"<kml><Placemark><Polygon><outerBoundaryIs><LinearRing><coordinates>1,1 2,2"
            b"</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark></kml>",
            "a polygon without area",  # two points: a face drawn edge-on, and nothing else
        ),
        (
            b"<kml><Placemark><ExtendedData><Data name='radius'><value>-5</value></Data>"
            b"</ExtendedData><Point><coordinates>1,2</coordinates></Point></Placemark></kml>",
            "radius must be a positive",
        ),
    ],
)
def test_kml_faults_are_one_line(tmp_path, rules, data, message):
    path = tmp_path / "bad.kml"
    path.write_bytes(data)
    with pytest.raises(InputError, match=message) as err:
        read_database([path], rules)
    assert "\n" not in str(err.value)


def test_kml_entities_are_not_expanded(tmp_path, rules):
    """No external entity is read, no entity expanded (XXE, a billion laughs)."""
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET")
    path = tmp_path / "xxe.kml"
    path.write_text(
        f'<?xml version="1.0"?><!DOCTYPE kml [<!ENTITY x SYSTEM "file://{secret}">'
        '<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>'
        "<kml><Placemark><name>&x;&b;</name><Polygon><outerBoundaryIs><LinearRing><coordinates>"
        "14.5,35.9 14.51,35.9 14.51,35.91 14.5,35.9</coordinates></LinearRing></outerBoundaryIs>"
        "</Polygon></Placemark></kml>"
    )
    (f,) = read_database([path], rules).features
    assert "TOPSECRET" not in str(f.tags) and "aaaa" not in str(f.tags)


def test_google_earth_drawings(rules):
    """Extruded to 120 m AGL, clamped to the ground (no band), a hole, a point with a radius,
    a path, and an operating area marked keep-in through ExtendedData."""
    got = by_name(read_database([EARTH], rules).features)
    stadium = got["Stadium (extruded to 120 m)"]
    assert (stadium.alt_min_m, stadium.alt_max_m) == (0.0, 120.0)
    assert stadium.properties == {"lower_reference": "AGL", "upper_reference": "AGL"}
    harbour = got["Harbour with a quay left open"]
    assert harbour.alt_min_m is None and harbour.alt_max_m is None
    assert len(harbour.geometry.interiors) == 1
    assert not harbour.geometry.covers(shapely.Point(14.5075, 35.886))
    helipad = got["Hospital helipad"]
    assert helipad.properties["circle"] == [14.47833, 35.90154, 150.0]
    local = LocalFrame(14.47833, 35.90154).geom_to_local(helipad.geometry)
    assert local.covers(shapely.Point(0, 0).buffer(150.0, quad_segs=128))
    assert got["Power line"].geomtype == "line" and got["Power line"].kind == "keep_out"
    block = got["Survey block"]
    assert (block.kind, block.category) == ("keep_in", "operating_area")
    assert {f.kind for n, f in got.items() if n != "Survey block"} == {"keep_out"}


def test_a_kml_placemark_without_geometry_is_counted(tmp_path, rules):
    path = tmp_path / "mixed.kml"
    path.write_text(
        EARTH.read_text().replace(
            "<Folder>", "<Folder><Placemark><name>Camera</name><Model/></Placemark>", 1
        )
    )
    db = read_database([path], rules)
    assert len(db.features) == 5
    assert db.skipped == Counter(
        {"KML placemark without a Polygon, LinearRing, LineString or Point": 1}
    )


def test_kml_bands_when_modes_differ_or_polygons_are_flat(tmp_path, rules):
    def one(geometry):
        path = tmp_path / "one.kml"
        path.write_text(f"<kml><Placemark>{geometry}</Placemark></kml>")
        (f,) = read_database([path], rules).features
        return f.alt_min_m, f.alt_max_m

    ring = "<outerBoundaryIs><LinearRing><coordinates>1,1,{z} 2,1,{z} 2,2,{z} 1,1,{z}"
    ring += "</coordinates></LinearRing></outerBoundaryIs>"

    def polygon(z, mode="absolute", extrude=0):
        return (
            f"<Polygon><extrude>{extrude}</extrude><altitudeMode>{mode}</altitudeMode>"
            f"{ring.format(z=z)}</Polygon>"
        )

    assert one(polygon(80)) == (None, None)  # a flat sheet: no band, a keep-out at any height
    assert one(polygon(80, extrude=1)) == (0.0, 80.0)
    assert one(f"<MultiGeometry>{polygon(50)}{polygon(90)}</MultiGeometry>") == (50.0, 90.0)
    mixed = f"<MultiGeometry>{polygon(50)}{polygon(90, 'relativeToGround')}</MultiGeometry>"
    assert one(mixed) == (None, None)
    assert one(polygon(80, "clampToGround", 1)) == (None, None)


def test_kml_without_lxml_is_one_line(tmp_path, monkeypatch, rules):
    import sys

    from alphafence.errors import MissingDependency

    monkeypatch.setitem(sys.modules, "lxml", None)
    monkeypatch.setitem(sys.modules, "lxml.etree", None)
    with pytest.raises(MissingDependency) as err:
        read_database([EARTH], rules)
    assert str(err.value).startswith(
        f"reading {EARTH} needs lxml: in the AlphaFence checkout: pip install '.[kml]'"
    )
    assert kml.looks_like_kml(EARTH.read_bytes()[:200])
