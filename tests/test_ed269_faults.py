"""ED-269 and ED-318 files with several malformed zones: every fault named at once, one line
each, nothing written; with ``--skip-invalid`` the malformed zones are left out whole, each
named, and the others fenced. Samples in tests/data/ed269 (the layouts InterUSS and EUROCAE
write), spoiled here."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from alphafence.cli import main
from alphafence.errors import InputError, InputErrors
from alphafence.zones.database import read_database

DATA = Path(__file__).parent / "data" / "ed269"


def _spoiled_ed269():
    """The UASZoneList sample plus two copies of its first zone, one with a limit that is no
    number, one with a vertex out of range."""
    doc = json.loads((DATA / "uaszonelist.json").read_text())
    first = doc["UASZoneList"][0]
    words = copy.deepcopy(first) | {"identifier": "ZL-BAD1"}
    words["geometry"][0]["upperLimit"] = "high"
    far = copy.deepcopy(first) | {"identifier": "ZL-BAD2"}
    far["geometry"][0]["horizontalProjection"]["coordinates"][0][1] = [8.5531, 97.3801]
    doc["UASZoneList"] += [words, far]
    return doc


def _spoiled_ed318():
    doc = json.loads((DATA / "ed318.json").read_text())
    doc["features"][0]["properties"].pop("type")
    doc["features"][2]["geometry"]["layer"]["uom"] = "furlong"
    return doc


def test_every_malformed_ed269_zone_is_named_at_once(write_json, rules):
    path = write_json("zones.json", _spoiled_ed269())
    with pytest.raises(InputErrors) as exc:
        read_database([path], rules)
    lines = str(exc.value).splitlines()
    assert lines[0] == f"{path}: 2 problems:"
    assert "zone ZL-BAD1: upperLimit must be a number, not 'high'" in lines[1]
    assert "zone ZL-BAD2: coordinate (8.5531, 97.3801) out of range" in lines[2]


def test_every_malformed_ed318_zone_is_named_at_once(write_json, rules):
    path = write_json("zones.json", _spoiled_ed318())
    with pytest.raises(InputErrors) as exc:
        read_database([path], rules)
    faults = [(e.feature, e.message) for e in exc.value.errors]
    assert faults[0] == ("zone E318P1", "missing zone type")
    assert faults[1][0] == "zone E318U3" and "uom" in faults[1][1]
    assert len(faults) == 2


def test_one_malformed_zone_is_one_line(write_json, rules):
    doc = _spoiled_ed269()
    doc["UASZoneList"].pop()
    with pytest.raises(InputError) as exc:
        read_database([write_json("zones.json", doc)], rules)
    assert not isinstance(exc.value, InputErrors) and "\n" not in str(exc.value)


@pytest.mark.parametrize("spoiled, kept", [(_spoiled_ed269, 2), (_spoiled_ed318, 1)])
def test_skip_invalid_leaves_malformed_zones_out_whole(write_json, rules, spoiled, kept):
    db = read_database([write_json("zones.json", spoiled())], rules, skip_invalid=True)
    assert len(db.invalid) == 2 and all(k["problem"] for k in db.invalid)
    named = {k["airspace"] for k in db.invalid}
    assert not any(f"zone {f.source}" in named for f in db.features)  # left out whole
    assert len({f.source for f in db.features}) == kept


def test_the_build_names_both_and_writes_nothing_then_skips_them(tmp_path, capsys):
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(_spoiled_ed269()))
    out = tmp_path / "f.geojson"
    assert main(["build", str(path), "-o", str(out), "-q"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "2 problems" in err and "ZL-BAD1" in err and "ZL-BAD2" in err
    assert "nothing was written; --skip-invalid leaves these zones out" in err
    assert not out.exists()
    assert main(["build", str(path), "-o", str(out), "--skip-invalid"]) == 0
    said = " ".join(capsys.readouterr().err.split())
    assert said.count("left out (--skip-invalid)") == 2 and out.exists()
    fenced = json.loads(out.read_text())["features"]
    assert fenced and not any("ZL-BAD" in json.dumps(f) for f in fenced)


def test_a_fault_skip_invalid_cannot_leave_out_gets_no_such_hint(tmp_path, capsys):
    path = tmp_path / "zones.json"
    path.write_text(json.dumps({"UASZoneList": "not a list"}))
    assert main(["build", str(path), "-o", str(tmp_path / "f.geojson"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "--skip-invalid" not in err
