"""The alphafence command, end to end, through its console entry point."""

import json
import os
import re
import subprocess
import sys

import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencefiles.qgc_plan import group_polygons, read_plan_fence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
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
        [exe, "demo", "-o", str(tmp_path), "--replay"], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr
    for name in ("fences.geojson", "fences.plan", "fences.waypoints", "fences.png", "compare.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert "synthetic" in res.stdout.lower() and "alpha" in res.stdout


# -- the command line's shape: negative values, errors and exit codes, entry points --------

AREA = "-0.58,51.42,-0.52,51.44"  # the demo scene lies west of Greenwich: negative longitudes


def test_a_negative_bbox_after_a_space_is_a_value(tmp_path, demo_fences, capsys):
    spaced = tmp_path / "spaced.geojson"
    joined = tmp_path / "joined.geojson"
    assert main(["build", str(scene_path()), "-o", str(spaced), "-q", "--bbox", AREA]) == 0
    assert main(["build", str(scene_path()), "-o", str(joined), "-q", f"--bbox={AREA}"]) == 0
    assert json.loads(spaced.read_text())["alphafence"]["bbox"] == [-0.58, 51.42, -0.52, 51.44]
    assert json.loads(spaced.read_text())["features"] == json.loads(joined.read_text())["features"]
    onboard = tmp_path / "onboard.plan"
    code = main(["compile", str(demo_fences), "--bbox", AREA, "-o", str(onboard)])
    assert code == 0 and read_plan_fence(onboard)
    upload = ["upload", str(demo_fences), "--bbox", AREA, "--dry-run", "--allow-unsigned"]
    assert main(upload) == 0
    assert "nothing sent" in capsys.readouterr().out


def test_a_negative_return_point_after_a_space_is_a_value(tmp_path, demo_fences):
    onboard = tmp_path / "onboard.plan"
    # a return point in the southern hemisphere is far from the area, but it is a position
    code = main(
        ["compile", str(demo_fences), "--bbox", AREA, "--return-point", "-35.36,149.16"]
        + ["-o", str(onboard)]
    )
    assert code == 0
    assert json.loads(onboard.read_text())["geoFence"]["breachReturn"][:2] == [-35.36, 149.16]


@pytest.mark.parametrize("verb", ["build", "compile"])
def test_a_bad_bbox_is_a_usage_error_for_every_verb(tmp_path, demo_fences, capsys, verb):
    args = {
        "build": ["build", str(scene_path()), "-o", str(tmp_path / "x.geojson")],
        "compile": ["compile", str(demo_fences), "-o", str(tmp_path / "x.plan")],
    }[verb]
    for bad, says in (
        ("1,2,3", "expected minlon,minlat,maxlon,maxlat, got '1,2,3'"),
        ("-0.5,51.4,-0.6,51.5", "min must be below max"),
        ("-190,51.4,-0.6,51.5", "coordinates out of range"),
    ):
        with pytest.raises(SystemExit) as exit_:
            main([*args, "--bbox", bad])
        assert exit_.value.code == 2
        assert f"alphafence {verb}: error: argument --bbox: {says}" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_an_empty_selection_names_the_bbox_option(tmp_path, capsys):
    out = tmp_path / "x.geojson"
    assert main(["build", str(scene_path()), "-o", str(out), "--bbox", "13,35,13.1,35.1"]) == 2
    err = capsys.readouterr().err
    assert "no restricted features inside --bbox 13,35,13.1,35.1" in err
    assert err.startswith("alphafence build: error: ") and err.count("\n") == 1


@pytest.mark.parametrize(
    "args, says",
    [
        (["--margin", "-1"], "alphafence build: error: --margin: must be a non-negative number"),
        (["--join", "nan"], "alphafence build: error: --join: must be a non-negative number"),
        (["--max-vertices", "3"], "alphafence build: error: --max-vertices: must be at least 4"),
        (["--alpha-radius", "0"], "--alpha-radius: must be a positive number of metres, not 0.0"),
        (["--warn-distance", "-5"], "--warn-distance: must be a non-negative number of metres"),
    ],
)
def test_out_of_range_values_are_one_line_input_errors(tmp_path, capsys, args, says):
    out = tmp_path / "x.geojson"
    assert main(["build", str(scene_path()), "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1
    assert not out.exists()


def test_a_value_that_is_not_a_number_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["build", str(scene_path()), "-o", "x.geojson", "--margin", "wide"])
    assert exit_.value.code == 2
    assert "argument --margin: invalid float value: 'wide'" in capsys.readouterr().err


def _errors():
    from alphafence.errors import AlphaFenceError, InputError, RoutingError, SitlError, VehicleError
    from alphafence.route.roadmap import NoRoute
    from alphafence.vehicle.bridge import BridgeError
    from alphafence.vehicle.fence_transfer import FenceTransferError
    from alphafence.vehicle.link import LinkError
    from alphafence.vehicle.params import ParamError
    from alphafence.vehicle.signing import SigningSetupError

    return [
        (InputError("f.geojson", "bad ring", "feature 3"), 2, "f.geojson: feature 3: bad ring"),
        (VehicleError("the vehicle refused"), 3, "the vehicle refused"),
        (LinkError("no heartbeat"), 3, "no heartbeat"),
        (BridgeError("udp://x: not a URL"), 3, "udp://x: not a URL"),
        (FenceTransferError("upload failed"), 3, "upload failed"),
        (ParamError("FENCE_ENABLE did not stick"), 3, "FENCE_ENABLE did not stick"),
        (SigningSetupError("not confirmed"), 3, "not confirmed"),
        (SitlError("no arducopter"), 1, "no arducopter"),
        (RoutingError("blocked"), 1, "blocked"),
        (NoRoute("the goal is enclosed"), 1, "the goal is enclosed"),
        (AlphaFenceError("something"), 1, "something"),
    ]


@pytest.mark.parametrize("error, code, says", _errors(), ids=lambda v: type(v).__name__)
def test_main_maps_each_error_to_its_exit_code(monkeypatch, capsys, error, code, says):
    def run(args):
        raise error

    monkeypatch.setattr("alphafence.cli.bundle.run", run)
    assert main(["bundle", "keygen", "--private", "k.pem", "--public", "k.pub"]) == code
    captured = capsys.readouterr()
    assert captured.err == f"alphafence bundle: error: {says}\n" and captured.out == ""


def test_main_maps_an_interrupt_to_130(monkeypatch, capsys):
    def run(args):
        raise KeyboardInterrupt

    monkeypatch.setattr("alphafence.cli.bundle.run", run)
    assert main(["bundle", "keygen", "--private", "k.pem", "--public", "k.pub"]) == 130
    assert capsys.readouterr().err == "alphafence: interrupted\n"


def test_an_error_while_parsing_names_the_verb(capsys):
    code = main(["route", "f.geojson", "--from", "95,14", "--to", "0,0", "-o", "m.plan"])
    assert code == 2
    assert capsys.readouterr().err == (
        "alphafence route: error: --from: coordinate (lat 95.0, lon 14.0) out of range\n"
    )


def test_every_verb_has_help():
    from alphafence.cli import VERBS

    for verb in VERBS:
        with pytest.raises(SystemExit) as exit_:
            main([verb, "--help"])
        assert exit_.value.code == 0, verb


def test_no_verb_module_imports_another():
    import ast
    from pathlib import Path

    import alphafence.cli
    from alphafence.cli import VERBS

    verbs = {f"alphafence.cli.{v.replace('-', '_')}" for v in VERBS}
    folder = Path(alphafence.cli.__file__).parent
    found = []
    for verb in sorted(verbs):
        tree = ast.parse((folder / f"{verb.rsplit('.', 1)[1]}.py").read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = {node.module} | {f"{node.module}.{a.name}" for a in node.names}
            elif isinstance(node, ast.Import):
                names = {a.name for a in node.names}
            else:
                continue
            found += [f"{verb} -> {n}" for n in sorted(names & (verbs - {verb}))]
    assert not found, found


def test_python_m_and_the_console_script_are_the_same_command(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "alphafence")
    runs = {
        name: [
            subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=120, cwd=tmp_path)
            for args in (["--help"], ["route", "f", "--from", "95,14", "--to", "0,0", "-o", "m"])
        ]
        for name, cmd in (("module", [sys.executable, "-m", "alphafence"]), ("script", [exe]))
    }
    for a, b in zip(runs["module"], runs["script"]):
        assert (a.returncode, a.stdout, a.stderr) == (b.returncode, b.stdout, b.stderr)
    help_, error = runs["script"]
    assert help_.returncode == 0 and help_.stdout.startswith("usage: alphafence")
    from alphafence.cli import VERBS

    listed = help_.stdout.split("positional arguments:")[1]
    assert [v for v in VERBS if not re.search(rf"^    {v}\s", listed, re.M)] == []
    assert error.returncode == 2 and error.stderr.startswith("alphafence route: error: --from:")
