"""KML/KMZ exports that draw each volume as a Folder of placemarks named for their part, as
national eAIPs publish them: ``NAME upper`` (the ceiling ring at its altitude), ``NAME lower``
(the floor ring), ``NAME side N`` (each wall a vertical quad, one of zero width where a vertex
repeats). Each volume is read from its folder as a whole: its floor and ceiling give the
footprint and band, and its walls add nothing, so the file builds without ``--skip-invalid``.
Checked against an independent parse of the sample (xml.etree, the names split here)."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from alphafence.cli import main
from alphafence.errors import InputError
from alphafence.zones.database import read_database
from tests.test_kml_great_circles import assert_held_both_ways

SAMPLE = Path(__file__).parent / "data" / "kml" / "eaip-folder-volumes.kml"
K = "{http://www.opengis.net/kml/2.2}"


def volumes(root):
    """(folder, zone name) -> {"upper": ring, "lower": ring, "sides": [ring, ...]}, rings of
    (lon, lat, alt), from the file as written."""
    out = {}
    for folder in root.iter(f"{K}Folder"):
        for pm in folder.findall(f"{K}Placemark"):
            name, part = re.fullmatch(
                r"(.+) (upper|lower|side \d+)", pm.findtext(f"{K}name")
            ).groups()
            text = pm.find(f".//{K}coordinates").text
            ring = [tuple(map(float, t.split(","))) for t in text.split()]
            v = out.setdefault((folder.findtext(f"{K}name"), name), {"sides": []})
            if part.startswith("side"):
                v["sides"].append(ring)
            else:
                v[part] = ring
    return out


def outline(ring):
    """A ring's (lon, lat) vertices, a repeated one once."""
    pts = [p[:2] for p in ring]
    return [p for k, p in enumerate(pts) if k == 0 or p != pts[k - 1]]


def kmz_of(tmp_path, root):
    path = tmp_path / "eaip.kmz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("doc.kml", ET.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return path


def test_the_sample_is_in_the_layout():
    truth = volumes(ET.parse(SAMPLE).getroot())
    assert len(truth) == 4 and len({folder for folder, _ in truth}) == 3  # two in one folder
    for v in truth.values():
        assert {"upper", "lower"} <= set(v) and len(v["sides"]) == len(v["upper"]) - 1
    zero = [s for v in truth.values() for s in v["sides"] if len({p[:2] for p in s}) == 1]
    assert zero, "no wall of zero width"


def test_each_folder_volume_is_one_keep_out_zone_up_to_its_ceiling(tmp_path, rules):
    root = ET.parse(SAMPLE).getroot()
    truth = volumes(root)
    db = read_database([kmz_of(tmp_path, root)], rules)
    got = {(f.tags["kml:folder"], f.name): f for f in db.features}
    assert sorted(got) == sorted(truth)
    for key, v in truth.items():
        f = got[key]
        assert f.kind == "keep_out"
        assert (f.alt_min_m, f.alt_max_m) == (v["lower"][0][2], v["upper"][0][2])
        assert f.properties["lower_reference"] == f.properties["upper_reference"] == "AMSL"
        assert_held_both_ways(f.geometry, [outline(v["upper"])])


def test_the_kmz_builds_without_skip_invalid(tmp_path, capsys):
    root = ET.parse(SAMPLE).getroot()
    out = tmp_path / "fences.geojson"
    assert main(["build", str(kmz_of(tmp_path, root)), "-o", str(out), "-q"]) == 0
    fences = json.loads(out.read_text())["features"]
    keep_out = sorted(f["properties"]["name"] for f in fences
                      if f["properties"]["kind"] == "keep_out")  # fmt: skip
    assert keep_out == sorted(name for _, name in volumes(root))
    assert "side" not in capsys.readouterr().err


def test_walls_give_the_outline_only_where_no_floor_or_ceiling_is(tmp_path, rules):
    # the volume whose ring repeats a vertex, its floor and ceiling taken away: its walls
    # (one of zero width) close the same ring, and it reads as before
    root = ET.parse(SAMPLE).getroot()
    truth = volumes(root)
    key = next(k for k, v in truth.items() if any(len({p[:2] for p in s}) == 1 for s in v["sides"]))
    for folder in root.iter(f"{K}Folder"):
        for pm in folder.findall(f"{K}Placemark"):
            if pm.findtext(f"{K}name") in (f"{key[1]} upper", f"{key[1]} lower"):
                folder.remove(pm)
    db = read_database([kmz_of(tmp_path, root)], rules)
    f = {(g.tags["kml:folder"], g.name): g for g in db.features}[key]
    assert (f.alt_min_m, f.alt_max_m) == (truth[key]["lower"][0][2], truth[key]["upper"][0][2])
    assert_held_both_ways(f.geometry, [outline(truth[key]["upper"])])


def test_placemarks_read_one_by_one_are_walls_that_close_nothing(tmp_path, rules):
    # broken on purpose: the same folders with every part renamed apart (no zone name to
    # group by) are read placemark by placemark, and each wall is refused, as before
    text = SAMPLE.read_text()
    n = iter(range(10_000))
    apart = re.sub(r"<name>(.+?) side (\d+)</name>", lambda m: f"<name>W{next(n)}</name>", text)
    path = tmp_path / "apart.kml"
    path.write_text(apart)
    with pytest.raises(InputError, match="vertical walls whose horizontal lines close no ring"):
        read_database([path], rules)
