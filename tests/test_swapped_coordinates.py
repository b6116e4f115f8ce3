"""Coordinates typed the wrong way round are caught: boxes are MINLON,MINLAT,MAXLON,MAXLAT
(GIS order) and positions LAT,LON (MAVLink's). A box that selects no fence while its swap
selects some, or a position far from every fence whose swap lies among them, exits 2 with one
line suggesting the swap; the value suggested is then taken. A compilation that selects no
fence at all exits 2 too, writing nothing."""

import re

import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.zones.mistakes import FAR_M, point_swap


@pytest.fixture(scope="module")
def fences(tmp_path_factory):
    out = tmp_path_factory.mktemp("fences") / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def extent(fences):
    """(minlon, minlat, maxlon, maxlat) of the fences, and a position inside it (lon, lat)."""
    geoms = [r.geometry for r in read_fences(fences)]
    bounds = shapely.total_bounds(geoms)
    return tuple(float(v) for v in bounds)


def _one_line(capsys):
    """The error: one line (upload's --allow-unsigned says so in a warning line before it)."""
    lines = [
        line for line in capsys.readouterr().err.splitlines() if not line.startswith("warning:")
    ]
    assert len(lines) == 1, lines
    return lines[0]


def _suggested(err, flag):
    found = re.search(rf"did you mean {flag} (\S+)\?$", err)
    assert found, err
    return found.group(1)


def _box(extent):
    """The fences' extent as typed for --bbox (lon,lat) and as typed the wrong way (lat,lon)."""
    minlon, minlat, maxlon, maxlat = extent
    right = f"{minlon:.4f},{minlat:.4f},{maxlon:.4f},{maxlat:.4f}"
    wrong = f"{minlat:.4f},{minlon:.4f},{maxlat:.4f},{maxlon:.4f}"
    return right, wrong


def _mid(extent):
    return (extent[0] + extent[2]) / 2, (extent[1] + extent[3]) / 2


@pytest.mark.parametrize("verb", ["compile", "upload"])
def test_a_box_typed_lat_lon_is_caught_and_its_swap_compiles(
    fences, extent, tmp_path, capsys, verb
):
    right, wrong = _box(extent)
    out = (
        ["-o", str(tmp_path / "o.plan")] if verb == "compile" else ["--dry-run", "--allow-unsigned"]
    )
    assert main([verb, str(fences), "--bbox", wrong, *out]) == 2
    err = _one_line(capsys)
    assert f"alphafence {verb}: error: --bbox: no fence of {fences}" in err
    assert _suggested(err, "--bbox") == right
    assert list(tmp_path.iterdir()) == []  # nothing written
    assert main([verb, str(fences), "--bbox", right, *out]) == 0


@pytest.mark.parametrize("verb", ["build", "compare"])
def test_a_database_box_typed_lat_lon_is_caught(extent, tmp_path, capsys, verb):
    right, wrong = _box(extent)
    out = ["-o", str(tmp_path / "f.geojson")] if verb == "build" else []
    assert main([verb, str(scene_path()), "--bbox", wrong, *out]) == 2
    err = _one_line(capsys)
    assert "no restricted features inside --bbox" in err and "features: did you mean" in err
    assert _suggested(err, "--bbox") == right
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flag", ["--from", "--to"])
def test_a_route_end_typed_lon_lat_is_caught_and_its_swap_routes(
    fences, extent, tmp_path, capsys, flag
):
    lon, lat = _mid(extent)
    # the other end: a corner of the fences' box, as typed LAT,LON
    other = f"{extent[1]:.5f},{extent[0]:.5f}"
    wrong, right = f"{lon:.5f},{lat:.5f}", f"{lat:.5f},{lon:.5f}"
    ends = {"--from": other, "--to": other, flag: wrong}
    argv = ["route", str(fences), "--from", ends["--from"], "--to", ends["--to"]]
    out = ["-o", str(tmp_path / "r.plan"), "--clearance", "0"]
    assert main([*argv, *out]) == 2
    err = _one_line(capsys)
    assert f"error: {flag}: {wrong} (LAT,LON) is " in err and f"every fence of {fences}" in err
    assert _suggested(err, flag) == right
    assert list(tmp_path.iterdir()) == []
    ends[flag] = right
    argv = ["route", str(fences), "--from", ends["--from"], "--to", ends["--to"]]
    code = main([*argv, *out])
    assert code in (0, 1), capsys.readouterr().err  # routed, or a route blocked: not a typo
    assert "did you mean" not in capsys.readouterr().err


def test_a_return_point_typed_lon_lat_is_caught(fences, extent, tmp_path, capsys):
    right_box, _ = _box(extent)
    lon, lat = _mid(extent)
    plan = str(tmp_path / "o.plan")
    argv = ["compile", str(fences), "--bbox", right_box, "-o", plan]
    assert main([*argv, "--return-point", f"{lon:.6f},{lat:.6f}"]) == 2
    assert _suggested(_one_line(capsys), "--return-point") == f"{lat:.6f},{lon:.6f}"
    assert main([*argv, "--return-point", f"{lat:.6f},{lon:.6f}"]) == 0


def test_a_box_that_selects_no_fence_writes_no_empty_plan(fences, extent, tmp_path, capsys):
    # a box far from the fences (the fences' box moved 2 degrees north): no swap selects
    # anything either, and the plan would leave the vehicle without a fence
    minlon, minlat, maxlon, maxlat = extent
    far = f"{minlon:.4f},{minlat + 2:.4f},{maxlon:.4f},{maxlat + 2:.4f}"
    for verb, out in (("compile", ["-o", str(tmp_path / "o.plan"), "--waypoints", str(tmp_path / "o.txt")]),
                      ("upload", ["--dry-run", "--allow-unsigned"])):  # fmt: skip
        assert main([verb, str(fences), "--bbox", far, *out]) == 2
        err = _one_line(capsys)
        assert f"{fences}: no keep-out or keep-in fence within 2000 m of the box" in err
        assert "without a fence" in err and "did you mean" not in err
    assert list(tmp_path.iterdir()) == []


def test_positions_as_typed_are_taken_when_no_swap_explains_them(fences, extent):
    geoms = [r.geometry for r in read_fences(fences)]
    lon, lat = _mid(extent)
    assert point_swap((lon, lat), geoms)[1] is None  # among the fences
    distance, swapped = point_swap((lon, lat - 3.0), geoms)  # 330 km south: far, no swap
    assert distance > FAR_M and swapped is None
    distance, swapped = point_swap((lat, lon), geoms)
    assert distance > FAR_M and swapped == pytest.approx((lon, lat))


def test_a_route_end_far_from_every_fence_is_refused_unless_asked(fences, extent, tmp_path, capsys):
    """``--to 40.0,7.43`` for Monaco's fences (a slip of a latitude, no swap): 414 km of
    ground the fences do not describe is refused; --beyond-fences routes it with a note."""
    lon, lat = _mid(extent)
    start, far = f"{lat:.5f},{lon:.5f}", f"{round(lat - 3.0, 2):g},{round(lon, 2):g}"
    out = ["-o", str(tmp_path / "r.plan"), "--clearance", "0"]
    argv = ["route", str(fences), "--from", start, "--to", far, *out]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert f"error: --to: {far} (LAT,LON) is 33" in err and "--beyond-fences" in err
    assert "did you mean" not in err
    assert list(tmp_path.iterdir()) == []
    assert main([*argv, "--beyond-fences"]) == 0
    captured = capsys.readouterr()
    assert f"note: --to {far} (LAT,LON) is 33" in " ".join(captured.out.split())
    assert (tmp_path / "r.plan").exists()
