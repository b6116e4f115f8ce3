"""Fence files other tools write, taken as fences by compile, route, check-mission and the
monitor (``read_fence_file``): a QGroundControl plan's geoFence, a fence ``.waypoints`` file,
ArduPilot's legacy fence file, KML/KMZ and OpenAir; inclusion kept as keep-in, exclusion as
keep-out, circles as circles. Each is checked against an independent parse of the file."""

import json
import zipfile
from pathlib import Path

import pytest
import shapely
from pyproj import Geod

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.fencefiles.qgc_wpl import waypoints_text
from alphafence.mavlink.items import FenceItem

DATA = Path(__file__).parent / "data"
AP = DATA / "ardupilot"
PLAN = AP / "fence.plan"
LEGACY = AP / "CMAC-legacy-fence.txt"
UK3D = DATA / "kml" / "uk-3d-zones.kml"
EARTH = DATA / "kml" / "google-earth.kml"
OPENAIR = DATA / "openair" / "sample.openair"
GEOD = Geod(ellps="WGS84")


def geodesic_circle(lon, lat, r, n=720):
    az = [360 * k / n for k in range(n)]
    lons, lats, _ = GEOD.fwd([lon] * n, [lat] * n, az, [r] * n)
    return shapely.points(list(zip(lons, lats)))


def test_a_plan_geofence_keeps_inclusion_exclusion_and_circles():
    doc = json.loads(PLAN.read_text())["geoFence"]
    got = {f.site_id: f for f in read_fence_file(PLAN)}
    assert set(got) == {"plan/polygon/0", "plan/polygon/1", "plan/circle/0"}
    for k, poly in enumerate(doc["polygons"]):
        f = got[f"plan/polygon/{k}"]
        assert f.kind == ("keep_in" if poly["inclusion"] else "keep_out")
        ring = list(f.geometry.exterior.coords)[:-1]
        assert ring == [(lon, lat) for lat, lon in poly["polygon"]]
        assert f.margin_m == 0 and f.alt_min_m is None and f.alt_max_m is None
    (circle,) = doc["circles"]
    f = got["plan/circle/0"]
    (lat, lon), r = circle["circle"]["center"], circle["circle"]["radius"]
    assert f.kind == "keep_out" and f.circle == (lon, lat, r)
    assert shapely.covers(f.geometry, geodesic_circle(lon, lat, r)).all()


def test_a_fence_waypoints_file_reads_as_the_plan_it_came_from(tmp_path):
    items = read_plan_fence(PLAN)
    path = tmp_path / "fence.waypoints"
    path.write_text(waypoints_text([FenceItem(5000, 0.0, 149.165085, -35.362938), *items]))
    plan = read_fence_file(PLAN)
    wpl = read_fence_file(path)
    assert [(f.kind, f.circle) for f in wpl] == [(f.kind, f.circle) for f in plan]
    for a, b in zip(plan, wpl):
        assert shapely.equals_exact(a.geometry, b.geometry, tolerance=1e-8)
        assert b.site_id == a.site_id.replace("plan/", "waypoints/")
    assert wpl[0].properties["return_point"] == [149.165085, -35.362938]


@pytest.mark.parametrize(
    "rows, message",
    [
        ([(5001, 0.0, 149.1, -35.3)], "vertex count \\(param1\\) must be a whole number >= 3"),
        ([(5002, 4.0, 149.1, -35.3)] * 3, "a polygon of 4 vertices has fewer items"),
        ([(5003, -5.0, 149.1, -35.3)], "circle radius -5.0 is not positive"),
        ([(5000, 0.0, 149.1, -35.3)], "no fence polygons or circles"),
    ],
)
def test_malformed_fence_items_are_one_line(tmp_path, rows, message):
    path = tmp_path / "bad.waypoints"
    path.write_text(waypoints_text([FenceItem(*r) for r in rows]))
    with pytest.raises(InputError, match=message) as err:
        read_fence_file(path)
    assert "\n" not in str(err.value)


def test_an_empty_plan_geofence_is_refused_not_read_as_no_fence(tmp_path):
    path = tmp_path / "empty.plan"
    path.write_text(json.dumps({"geoFence": {"version": 2, "polygons": [], "circles": []}}))
    with pytest.raises(InputError, match="no fence polygons or circles"):
        read_fence_file(path)


def test_ardupilot_legacy_fence_is_one_keep_in_polygon():
    lines = [tuple(map(float, line.split())) for line in LEGACY.read_text().splitlines()]
    (f,) = read_fence_file(LEGACY)  # a .txt: told by its content
    assert f.kind == "keep_in" and f.site_id == "legacy/polygon"
    assert f.properties["return_point"] == [lines[0][1], lines[0][0]]
    assert list(f.geometry.exterior.coords) == [(lon, lat) for lat, lon in lines[1:]]


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "-35.36 149.16\n-35.35 149.15\n-35.35 149.17\n-35.37 149.17\n-35.37 149.15\n",
            "must repeat the first polygon point",
        ),
        ("-35.36 149.16\n-35.35 149.15\n-35.35 149.17\n-35.35 149.15\n", "4 points"),
        ("# fence\n-35.36 149.16\n-35.35 149.15 12\n", "line 3: expected 'lat lon'"),
        (
            "-95.36 149.16\n-35.35 149.15\n-35.35 149.17\n-35.37 149.17\n-35.35 149.15\n",
            "line 1: coordinate \\(lat -95.36",
        ),
    ],
)
def test_malformed_legacy_fences_are_one_line(tmp_path, text, message):
    path = tmp_path / "fence.txt"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_fence_file(path)
    assert "\n" not in str(err.value)


def test_a_txt_is_told_by_its_content(tmp_path):
    wpl = tmp_path / "fence.txt"
    wpl.write_text(waypoints_text(read_plan_fence(PLAN)))
    assert [f.site_id for f in read_fence_file(wpl)][0] == "waypoints/polygon/0"
    oa = tmp_path / "airspace.txt"
    oa.write_bytes(OPENAIR.read_bytes())
    assert len(read_fence_file(oa)) == 6
    unknown = tmp_path / "zones.dat"
    unknown.write_bytes(UK3D.read_bytes())
    assert len(read_fence_file(unknown)) == 3


def test_kml_zones_are_keep_out_fences_with_their_bands(tmp_path):
    kmz = tmp_path / "zones.kmz"
    with zipfile.ZipFile(kmz, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(UK3D, "doc.kml")
    for path in (UK3D, kmz):
        got = {f.name: f for f in read_fence_file(path)}
        assert {f.kind for f in got.values()} == {"keep_out"}
        r = got["EG R997 TEST RESTRICTED"]
        assert (r.alt_min_m, r.alt_max_m) == (152.4, 609.6) and r.margin_m == 0
        assert r.properties["lower_reference"] == "AGL"


def test_kml_keep_in_through_extended_data_and_circles(tmp_path):
    text = EARTH.read_text()
    start = text.index("\t\t<Placemark>\n\t\t\t<name>Power line")
    end = text.index("</Placemark>", start) + len("</Placemark>")
    path = tmp_path / "area.kml"
    path.write_text(text[:start] + text[end:])  # a path is no fence: left out here
    got = {f.name: f for f in read_fence_file(path)}
    assert got["Survey block"].kind == "keep_in"
    assert got["Hospital helipad"].circle == (14.47833, 35.90154, 150.0)
    assert got["Stadium (extruded to 120 m)"].alt_max_m == 120.0
    with pytest.raises(InputError, match="placemark/3 \\(Power line\\): a fence must be an area"):
        read_fence_file(EARTH)


def test_openair_airspaces_as_fences():
    got = {f.name: f for f in read_fence_file(OPENAIR)}
    assert len(got) == 6 and {f.kind for f in got.values()} == {"keep_out"}
    prison = got["EGP998 PRISON"]
    assert prison.circle[2] == pytest.approx(1.5 * 1852) and prison.site_id == "airspace/openair/1"
    assert prison.alt_max_m == pytest.approx(1981.2)


# -- the command line --------------------------------------------------------------------


def test_build_from_a_kmz_gives_keep_out_fences_with_the_band(tmp_path):
    kmz = tmp_path / "eaip3d.kmz"
    with zipfile.ZipFile(kmz, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(UK3D, "eaip3d-test.kml")
    out = tmp_path / "x.geojson"
    assert main(["build", str(kmz), "-o", str(out), "-q"]) == 0
    fences = read_fences(out)
    keep_out = {f.name: f for f in fences if f.kind == "keep_out"}
    assert set(keep_out) == {
        "EG D999 TEST DANGER",
        "EG P998 TEST PROHIBITED",
        "EG R997 TEST RESTRICTED",
    }
    r = keep_out["EG R997 TEST RESTRICTED"]
    assert (r.alt_min_m, r.alt_max_m) == (152.4, 609.6) and r.category == "airspace"
    assert r.properties["zone"] == {"lower_reference": "AGL", "upper_reference": "AGL"}
    assert keep_out["EG D999 TEST DANGER"].alt_max_m == 304.8


@pytest.mark.parametrize(
    "mission, fences, code, verdict",
    [
        ("through-circle.waypoints", PLAN, 1, "plan/circle/0"),
        ("leaves-area.waypoints", PLAN, 1, "plan/polygon/0 (keep-in)"),
        ("clear.waypoints", PLAN, 0, "0 cross a keep-out fence"),
        ("leaves-area.waypoints", LEGACY, 1, "legacy/polygon (keep-in)"),
        ("clear.waypoints", LEGACY, 0, "4 clear"),
    ],
)
def test_check_mission_takes_plan_and_legacy_fences(capsys, mission, fences, code, verdict):
    assert main(["check-mission", str(AP / mission), "--fences", str(fences)]) == code
    assert verdict in capsys.readouterr().out


def test_compile_and_the_monitor_take_a_plan_and_a_kml(tmp_path):
    from alphafence.awareness.fenceset import FenceSet

    out = tmp_path / "onboard.plan"
    args = ["compile", str(PLAN), "--bbox", "149.15,-35.375,149.18,-35.35", "-o", str(out)]
    assert main(args) == 0
    fence = json.loads(out.read_text())["geoFence"]
    assert [p["inclusion"] for p in fence["polygons"]] == [True, False]
    (circle,) = fence["circles"]  # grown a little: its centre rounded to 1e-7 degrees
    assert circle["inclusion"] is False and 80 <= circle["circle"]["radius"] < 80.5
    fences = FenceSet.from_geojson(UK3D)
    assert len(fences.records) == 3 and fences.alt_max.max() == 731.5
