"""Repair never shrinks: every point a file draws (vertices, arc points, a spike out to a
vertex and back, both lobes of a crossing outline, repeated and near-repeated vertices) lies
inside the zone's own fence plus its margin, as ArduPilot reads the fence, for every method.
Property-tested on drawn outlines, and on an OpenAir sample with a spike and an arc that
crosses its own outline; KML volumes with a face drawn edge-on keep the footprint of their
other faces, and a malformed placemark is named with every other one (or left out with
``--skip-invalid``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from alphafence.cli import main
from alphafence.fencing.fences import METHODS
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.frame import LocalFrame

from .ardupilot_model import excursion_m
from .test_as_read_properties import _rings, _rules
from .zone_samples import zone_features

FRAME = LocalFrame(14.5, 35.9)


def drawn_points(outline):
    """Every vertex of a lon/lat outline, as points."""
    return shapely.MultiPoint(np.asarray(outline, float))


def assert_drawn_inside(outline, zone, method, margin):
    rules = _rules("keep_out", margin)
    result = build_fences(zone_features([zone], rules), rules, BuildOptions(method=method))
    fences = [f for f in result.fences if f.kind == "keep_out"]
    assert fences, "the zone has no fence"
    rings = [r for f in fences for r in _rings(f.geometry)]
    out = excursion_m(drawn_points(outline), rings, margin)
    assert out <= 0.01, f"{method}: a point the file draws lies {out:.2f} m beyond the fence"


def _metres(points):
    lon, lat = FRAME.to_wgs84(*np.asarray(points, float).T)
    return list(zip(np.asarray(lon).tolist(), np.asarray(lat).tolist()))


@st.composite
def broken_outlines(draw):
    """A 1-2 km square drawn with a fault: a spike out to a vertex and straight back, a
    bow-tie, repeated or near-repeated vertices, or an outline that crosses itself."""
    size = draw(st.floats(1000.0, 2000.0))
    kind = draw(st.sampled_from(["spike", "bowtie", "repeated", "near-repeated", "crossing"]))
    s = size
    if kind == "spike":
        reach = draw(st.floats(50.0, 900.0))
        pts = [(0, 0), (s, 0), (s, s / 2), (s + reach, s / 2 + draw(st.floats(-50, 50))),
               (s, s / 2), (s, s), (0, s)]  # fmt: skip
    elif kind == "bowtie":
        pts = [(0, 0), (s, s), (s, 0), (0, s)]
    elif kind == "repeated":
        pts = [(0, 0), (s, 0), (s, 0), (s, s), (0, s), (0, s)]
    elif kind == "near-repeated":
        e = draw(st.floats(1e-3, 0.05))
        pts = [(0, 0), (s, 0), (s + e, e), (s, s), (0, s)]
    else:  # a lobe beyond the outline, as an arc drawn the wrong way round makes one
        pts = [(0, 0), (s, 0), (s, s), (s / 2, -s / 3), (0, s)]
    return kind, _metres(pts)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(outline=broken_outlines(), margin=st.sampled_from([0.0, 10.0, 100.0]))
@pytest.mark.parametrize("method", METHODS)
def test_every_point_a_broken_outline_draws_is_fenced(method, outline, margin):
    kind, pts = outline
    zone = shapely.Polygon(pts)
    event(f"{kind} ({'valid' if zone.is_valid else 'invalid'})")
    assert_drawn_inside(pts, zone, method, margin)


def test_a_spike_dropped_by_repair_is_seen():
    """The check fails on the repair that dropped a spike: its fence misses the spike's tip."""
    pts = _metres([(0, 0), (1000, 0), (1000, 500), (1600, 500), (1000, 500), (1000, 1000),
                   (0, 1000)])  # fmt: skip
    dropped = shapely.buffer(shapely.Polygon(pts), 0)  # GEOS densifier's repair: no spike
    assert dropped.geom_type == "Polygon"
    with pytest.raises(AssertionError, match="beyond the fence"):
        assert_drawn_inside(pts, dropped, "alpha", 10.0)


OPENAIR = """\
* a zone whose outline runs out to a vertex and back, and one whose arc crosses its outline
AC R
AN SPIKE ONE
AL GND
AH 2000ft AMSL
DP 35:54:00 N 014:30:00 E
DP 35:54:00 N 014:31:12 E
DP 35:54:18 N 014:31:12 E
DP 35:54:22 N 014:31:48 E
DP 35:54:18 N 014:31:12 E
DP 35:54:36 N 014:31:12 E
DP 35:54:36 N 014:30:00 E

AC R
AN ARC ACROSS
AL GND
AH 2000ft AMSL
V X=35:56:00 N 014:31:00 E
DP 35:55:30 N 014:30:00 E
DP 35:55:30 N 014:32:00 E
DB 35:55:30 N 014:32:00 E,35:56:30 N 014:32:00 E
DP 35:56:30 N 014:30:00 E
"""


def _dms(text):
    d, m, s = (float(v) for v in text.split(":"))
    return d + m / 60 + s / 3600


def test_an_openair_spike_and_crossing_arc_are_fenced(tmp_path):
    path = tmp_path / "zones.txt"
    path.write_text(OPENAIR)
    out = tmp_path / "f.geojson"
    assert main(["build", str(path), "-o", str(out), "--margin", "10", "-q"]) == 0
    doc = json.loads(out.read_text())
    rings = [r for f in doc["features"] if f["properties"]["kind"] == "keep_out"
             for r in _rings(shapely.geometry.shape(f["geometry"]))]  # fmt: skip
    tip = shapely.Point(_dms("014:31:48"), _dms("35:54:22"))  # the spike's vertex
    assert excursion_m(tip, rings, 10.0) <= 0.01
    corners = [(_dms("014:30:00"), _dms(y)) for y in ("35:55:30", "35:56:30")]
    assert excursion_m(shapely.MultiPoint(corners), rings, 10.0) <= 0.01


def kml(faces):
    """An eAIP-style KML: one zone's volume as placemarks in a Folder (floor, ceiling),
    altitudes absolute."""
    marks = "".join(
        f"<Placemark><name>EGD999</name><Polygon><altitudeMode>absolute</altitudeMode>"
        f"<outerBoundaryIs><LinearRing><coordinates>{coords}</coordinates></LinearRing>"
        f"</outerBoundaryIs></Polygon></Placemark>"
        for coords in faces
    )
    return ('<?xml version="1.0" encoding="UTF-8"?><kml xmlns="http://www.opengis.net/kml/2.2">'
            f"<Document><Folder><name>EGD999</name>{marks}</Folder></Document></kml>")  # fmt: skip


FLOOR = "14.50,35.90,0 14.52,35.90,0 14.52,35.92,0 14.50,35.92,0 14.50,35.90,0"
EDGE_ON = "14.50,35.90,600 14.52,35.90,600 14.50,35.90,600"  # a ceiling of three coordinates


def test_a_kml_volume_with_a_face_drawn_edge_on_keeps_its_footprint(tmp_path):
    path = tmp_path / "eaip.kml"
    path.write_text(kml([FLOOR, EDGE_ON]))
    out = tmp_path / "f.geojson"
    assert main(["build", str(path), "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    (fence,) = [f for f in doc["features"] if f["properties"]["kind"] == "keep_out"]
    assert shapely.geometry.shape(fence["geometry"]).covers(shapely.box(14.50, 35.90, 14.52, 35.92))
    assert fence["properties"]["alt_max_m"] == pytest.approx(600.0)


BROKEN = "14.50,35.90 14.52,abc"


def test_every_malformed_placemark_is_named_at_once_or_left_out(tmp_path, capsys):
    path = tmp_path / "eaip.kml"
    path.write_text(
        kml([FLOOR, BROKEN, BROKEN]).replace("EGD999</name><Polygon>", "X</name><Polygon>", 0)
    )
    out = tmp_path / "f.geojson"
    assert main(["build", str(path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "2 problems" in err and err.count("malformed coordinates") == 2
    assert not out.exists()
    assert main(["build", str(path), "-o", str(out), "--skip-invalid"]) == 0
    said = " ".join(capsys.readouterr().err.split())
    assert said.count("left out (--skip-invalid)") == 2 and out.exists()


def test_skip_invalid_leaves_out_malformed_geojson_features_naming_each(tmp_path, capsys):
    good = {"type": "Feature", "properties": {"amenity": "hospital", "osm_id": "1"},
            "geometry": shapely.geometry.mapping(shapely.box(14.50, 35.90, 14.51, 35.91))}  # fmt: skip
    bad = {"type": "Feature", "properties": {"amenity": "hospital"},
           "geometry": {"type": "LineString", "coordinates": [[14.5, 35.9]]}}  # fmt: skip
    path = tmp_path / "zones.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [good, bad, bad]}))
    out = tmp_path / "f.geojson"
    assert main(["build", str(path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err  # both at once, one line each, and what would build
    assert "2 problems" in err and not out.exists()
    assert "--skip-invalid leaves these zones out" in " ".join(err.split())
    assert "feature 1: malformed LineString" in err and "feature 2: malformed LineString" in err
    assert main(["build", str(path), "-o", str(out), "--skip-invalid"]) == 0
    said = " ".join(capsys.readouterr().err.split())
    assert said.count("left out (--skip-invalid)") == 2 and "feature 2" in said
    assert out.exists()
