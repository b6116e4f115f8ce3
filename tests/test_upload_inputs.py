"""``upload`` tells an onboard fence file by its content, not by a ``.txt`` suffix: ArduPilot's
legacy fence file (``lat lon`` lines, as MAVProxy's ``fence save`` and ArduPilot's autotest
write it, usually ``.txt``) is sent as its return point and inclusion polygon; a QGC WPL file
named ``.txt`` is read as waypoints; other ``.txt`` files (OpenAir) are compiled. And
``check-mission --fences`` says it takes any fence file."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.upload import load_items
from alphafence.mavlink.items import POLYGON_INCLUSION, RETURN_POINT

DATA = Path(__file__).parent / "data"
LEGACY = DATA / "ardupilot" / "CMAC-legacy-fence.txt"


def legacy_points(path):
    """An independent parse: (lat, lon) per line that is no comment."""
    rows = [ln.split() for ln in Path(path).read_text().splitlines()]
    return [(float(a), float(b)) for a, b in (r for r in rows if r and not r[0].startswith("#"))]


def items_of(path, **kw):
    args = argparse.Namespace(fences=str(path), area=None, bbox=None, **kw)
    items, compiled = load_items(args)
    assert compiled is None
    return items


def test_a_legacy_fence_txt_is_its_return_point_and_inclusion_polygon():
    pts = legacy_points(LEGACY)
    items = items_of(LEGACY)
    assert items[0].command == RETURN_POINT and (items[0].lat, items[0].lon) == pts[0]
    poly = items[1:]
    ring = pts[1:-1]  # the closing repeat is not sent
    assert all(it.command == POLYGON_INCLUSION and it.param1 == len(ring) for it in poly)
    assert sorted((it.lat, it.lon) for it in poly) == sorted(ring)
    sent = shapely.Polygon([(it.lon, it.lat) for it in poly])
    assert sent.equals(shapely.Polygon([(lon, lat) for lat, lon in ring]))


def test_upload_dry_run_of_a_legacy_fence_by_its_content(tmp_path, capsys):
    for name in ("fence.txt", "fence.fen"):  # told by content, whatever the suffix
        path = tmp_path / name
        shutil.copy(LEGACY, path)
        assert main(["upload", str(path), "--dry-run", "--allow-unsigned"]) == 0
        out = capsys.readouterr().out
        assert "return point" in out and "inclusion polygon" in out
        assert "6 fence items ready" in out


def test_a_qgc_wpl_fence_named_txt_is_still_read_as_waypoints(tmp_path):
    path = tmp_path / "fence.txt"
    shutil.copy(DATA / "qgc" / "fence-76-items.waypoints", path)
    assert len(items_of(path)) == 76


def test_an_openair_txt_is_compiled_for_the_area(tmp_path, capsys):
    path = tmp_path / "airspace.txt"
    shutil.copy(DATA / "openair" / "sample.openair", path)
    argv = ["upload", str(path), "--dry-run", "--allow-unsigned"]
    assert main(argv) == 2
    assert "need an operating area" in capsys.readouterr().err
    assert main([*argv, "--bbox", "-1.5,52.1,-1.2,52.25"]) == 0
    assert "fence items ready" in capsys.readouterr().out


def test_check_mission_help_names_every_fence_file_it_reads(capsys):
    """``check-mission --fences`` reads any fence file read_fence_file reads, not only GeoJSON."""
    with pytest.raises(SystemExit):
        main(["check-mission", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "fence GeoJSON" not in text
    for fmt in (".plan", ".waypoints", "legacy fence", "KML", "OpenAir", "GeoParquet"):
        assert fmt in text, fmt
