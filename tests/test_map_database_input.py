"""A map database (an OpenStreetMap extract, a geozone list, an SQLite file) given where
fences belong is refused in one line that says to build fences of it first, by every verb
that reads fences."""

import json
import struct

import pytest

from alphafence.cli import main
from alphafence.zones.mistakes import map_database_kind

MISSION = "tests/data/ardupilot/clear.waypoints"


def _pbf_head():
    """The start of an OSM PBF file as the PBF format lays it out: a 4-byte big-endian
    length, a BlobHeader (type "OSMHeader", datasize), then the Blob (raw_size, zlib_data)."""
    blob = b"\x10\x05" + b"\x1a\x05" + b"\x78\x9c\x03\x00\x00"
    header = b"\x0a\x09OSMHeader" + b"\x18" + bytes([len(blob)])
    return struct.pack(">I", len(header)) + header + blob + b"\x00" * 40


def _verbs(fences, tmp_path):
    return {
        "compile": ["compile", fences, "--bbox", "7.40,43.72,7.44,43.75", "-o", f"{tmp_path}/o.plan"],
        "upload": ["upload", fences, "--bbox", "7.40,43.72,7.44,43.75", "--dry-run"],
        "route": ["route", fences, "--from", "43.73,7.41", "--to", "43.74,7.43", "-o", f"{tmp_path}/r.plan"],
        "check-mission": ["check-mission", MISSION, "--fences", fences],
        "monitor": ["monitor", "--connect", "udpin://127.0.0.1:9", "--fences", fences, "--allow-unsigned"],
        "check-flight": ["check-flight", f"{tmp_path}/none.tlog", "--fences", fences],
    }  # fmt: skip


@pytest.mark.parametrize(
    "verb", ["compile", "upload", "route", "check-mission", "monitor", "check-flight"]
)
@pytest.mark.parametrize(
    "name, command",
    [
        ("monaco.osm.pbf", "alphafence build {p} -o fences.geojson"),
        # told by its first bytes whatever its name: renamed for build, which goes by suffix
        (
            "download.bin",
            "renamed .osm.pbf: alphafence build {d}/download.osm.pbf -o fences.geojson",
        ),
    ],
)
def test_an_osm_extract_where_fences_belong_says_build_first(tmp_path, capsys, verb, name, command):
    pbf = tmp_path / name
    pbf.write_bytes(_pbf_head())
    code = main(_verbs(str(pbf), tmp_path)[verb])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.count("\n") == 0, err
    assert f"{pbf}: a map database (an OpenStreetMap" in err and "not fences" in err
    assert command.format(p=pbf, d=tmp_path) in err
    assert "UTF-8" not in err and "JSON" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # nothing written


def test_osm_xml_and_sqlite_are_told_by_their_first_bytes(tmp_path, capsys):
    xml = tmp_path / "export.xml"
    xml.write_text('<?xml version="1.0" encoding="UTF-8"?>\n<osm version="0.6" generator="x">\n')
    assert main(["check-mission", MISSION, "--fences", str(xml)]) == 2
    err = capsys.readouterr().err
    assert (
        "OpenStreetMap XML extract" in err and f"alphafence build {tmp_path}/export.osm -o" in err
    )
    gpkg = tmp_path / "zones.data"
    gpkg.write_bytes(b"SQLite format 3\x00" + b"\x00" * 84)
    assert main(["check-mission", MISSION, "--fences", str(gpkg)]) == 2
    err = capsys.readouterr().err
    assert "SQLite database" in err and "not one alphafence build reads" in err


def test_map_features_and_geozone_lists_say_build_first(tmp_path, capsys):
    osm = tmp_path / "hospitals.geojson"
    square = [[[7.42, 43.73], [7.43, 43.73], [7.43, 43.74], [7.42, 43.73]]]
    feature = {"type": "Feature", "properties": {"amenity": "hospital"},
               "geometry": {"type": "Polygon", "coordinates": square}}  # fmt: skip
    osm.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    assert main(["check-mission", MISSION, "--fences", str(osm)]) == 2
    err = capsys.readouterr().err
    assert "GeoJSON map features" in err and f"alphafence build {osm} -o fences.geojson" in err
    for zones in ("tests/data/ed269/uaszonelist.json", "tests/data/ed269/ed318.json"):
        assert main(["check-mission", MISSION, "--fences", zones]) == 2
        err = capsys.readouterr().err
        assert "geozone list" in err and f"alphafence build {zones} -o fences.geojson" in err


def test_fence_files_are_no_map_database(tmp_path):
    # what the kit reads as fences, KMZ (a zip) and a fence plan included, is never refused
    for path in ("tests/data/ardupilot/fence.plan", "tests/data/ardupilot/CMAC-legacy-fence.txt"):
        assert map_database_kind(path) is None
    for data in (b"PK\x03\x04" + b"\x00" * 40, b'{"type": "FeatureCollection"}', b"AC R\n"):
        (tmp_path / "f.kmz").write_bytes(data)
        assert map_database_kind(tmp_path / "f.kmz") is None


def test_a_real_extract_is_refused(monaco, tmp_path, capsys):
    renamed = tmp_path / "monaco.dat"
    renamed.symlink_to(monaco)
    assert main(["route", str(renamed), "--from", "43.73,7.41", "--to", "43.74,7.43",
                 "-o", str(tmp_path / "r.plan")]) == 2  # fmt: skip
    assert "a map database (an OpenStreetMap PBF extract)" in capsys.readouterr().err
