"""The alphafence command, end to end, through its console entry point."""

import json
import os
import subprocess
import sys

import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.formats.qgc_plan import group_polygons, read_plan_fence
from alphafence.formats.qgc_wpl import read_waypoints_fence
from alphafence.mavlink.items import POLYGON_EXCLUSION

PNG = b"\x89PNG\r\n\x1a\n"


def test_build_writes_geojson_plan_waypoints_and_map(tmp_path, capsys):
    out = tmp_path / "fences.geojson"
    code = main(
        [
            "build",
            str(scene_path()),
            "-o",
            str(out),
            "--plan",
            str(tmp_path / "f.plan"),
            "--waypoints",
            str(tmp_path / "f.waypoints"),
            "--figure",
            str(tmp_path / "map.png"),
        ]
    )
    assert code == 0
    doc = json.loads(out.read_text())
    props = [f["properties"] for f in doc["features"]]
    keys = {
        "site_id",
        "name",
        "category",
        "kind",
        "method",
        "margin_m",
        "alt_min_m",
        "alt_max_m",
        "vertices",
        "area_m2",
        "sources",
    }
    assert all(keys <= set(p) for p in props)
    assert {p["kind"] for p in props} == {"keep_out", "warning"}
    hospital = [p for p in props if p["category"] == "hospital" and p["kind"] == "keep_out"]
    assert max(len(p["sources"]) for p in hospital) >= 5  # the campus is one site
    keep_out = [f for f in doc["features"] if f["properties"]["kind"] == "keep_out"]
    # the plan and the waypoint file carry the same exclusion polygons, in lat/lon order
    plan = json.loads((tmp_path / "f.plan").read_text())
    assert plan["fileType"] == "Plan" and plan["geoFence"]["version"] == 2
    assert len(plan["geoFence"]["polygons"]) == len(keep_out)
    lat, lon = plan["geoFence"]["polygons"][0]["polygon"][0]
    assert 51.4 < lat < 51.5 and -0.6 < lon < -0.5
    a = read_plan_fence(tmp_path / "f.plan")
    b = read_waypoints_fence(tmp_path / "f.waypoints")
    assert len(a) == len(b) and all(x.command == POLYGON_EXCLUSION for x in a)
    assert all(abs(x.lat - y.lat) < 1e-7 and abs(x.lon - y.lon) < 1e-7 for x, y in zip(a, b))
    polys, _ = group_polygons(a)
    geo = shapely.geometry.shape(keep_out[0]["geometry"])
    plan_poly = shapely.Polygon(polys[0][1])
    assert plan_poly.symmetric_difference(geo).area < 1e-9  # same polygon up to GeoJSON rounding
    assert (tmp_path / "map.png").read_bytes().startswith(PNG)
    assert "sites from" in capsys.readouterr().out


def test_bad_input_exits_2_with_one_line_and_leaves_no_output(tmp_path, capsys):
    bad = tmp_path / "bad.geojson"
    bad.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"amenity": "prison", "osm_way_id": "42"},
                        "geometry": {
                            "type": "Polygon",
                            "coordinates": [[[14, 35], [14, 95], [15, 35], [14, 35]]],
                        },
                    }
                ],
            }
        )
    )
    out = tmp_path / "fences.geojson"
    code = main(["build", str(bad), "-o", str(out), "--plan", str(tmp_path / "f.plan")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.count("\n") == 0 and str(bad) in err and "way/42" in err and "out of range" in err
    assert list(tmp_path.iterdir()) == [bad]


def test_existing_output_survives_a_failed_build(tmp_path):
    out = tmp_path / "fences.geojson"
    out.write_text("previous fences")
    code = main(["build", str(tmp_path / "missing.osm.pbf"), "-o", str(out)])
    assert code == 2 and out.read_text() == "previous fences"


def test_methods_and_alpha_radius(tmp_path):
    areas = {}
    for method in ("alpha", "polygon", "circle", "exact"):
        out = tmp_path / f"{method}.geojson"
        assert (
            main(
                [
                    "build",
                    str(scene_path()),
                    "-o",
                    str(out),
                    "--method",
                    method,
                    "-q",
                    "--warn-distance",
                    "0",
                ]
            )
            == 0
        )
        feats = json.loads(out.read_text())["features"]
        assert {f["properties"]["method"] for f in feats} == {method}
        areas[method] = sum(f["properties"]["area_m2"] for f in feats)
    assert areas["exact"] <= areas["alpha"] < areas["polygon"] < areas["circle"]
    out = tmp_path / "forced.geojson"
    assert (
        main(
            [
                "build",
                str(scene_path()),
                "-o",
                str(out),
                "--alpha-radius",
                "5",
                "--margin",
                "0",
                "-q",
            ]
        )
        == 0
    )
    forced = json.loads(out.read_text())["features"]
    assert any(
        f["geometry"]["type"] == "MultiPolygon" for f in forced
    )  # 5 m does not bridge the campus


def test_compare_json_and_figure(tmp_path, capsys):
    fig = tmp_path / "cmp.png"
    assert main(["compare", str(scene_path()), "--json", "--figure", str(fig)]) == 0
    doc = json.loads(capsys.readouterr().out)
    stats = {m["method"]: m for m in doc["methods"]}
    assert set(stats) == {"alpha", "polygon", "circle", "exact"}
    assert all(m["containment_pct"] == pytest.approx(100.0) for m in stats.values())
    assert (
        stats["alpha"]["overshoot"] < stats["polygon"]["overshoot"] < stats["circle"]["overshoot"]
    )
    assert fig.read_bytes().startswith(PNG)


def test_bad_options(capsys):
    assert main(["compare", str(scene_path()), "--methods", "alpha,hexagon"]) == 2
    assert "unknown method(s) hexagon" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["build", str(scene_path()), "-o", "x.geojson", "--bbox", "1,2,3"])


def test_console_script_runs_the_demo(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "alphafence")
    res = subprocess.run(
        [exe, "demo", "-o", str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr
    for name in ("fences.geojson", "fences.plan", "fences.waypoints", "fences.png", "compare.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert "synthetic" in res.stdout.lower() and "alpha" in res.stdout
