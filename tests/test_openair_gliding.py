"""OpenAir files as gliding tools write them: every altitude form read to its metres and
reference, limits without a numeric meaning widened with a note, and every fault of a file
reported at once (or, asked for, the airspaces at fault left out and named)."""

from collections import Counter
from pathlib import Path

import pytest

from alphafence.errors import InputError, InputErrors
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.zones import openair
from alphafence.zones.database import read_database
from alphafence.zones.openair_alt import Unreadable, read_altitude
from alphafence.zones.rules import parse_rules

DATA = Path(__file__).parent / "data" / "openair"
GLIDING = DATA / "gliding.openair"
FAULTS = DATA / "gliding-faults.openair"
FT = 0.3048


def lines_of(path):
    """The file's lines (1-based, CR LF removed), read apart from the reader."""
    return {n: t.rstrip("\r\n") for n, t in enumerate(path.read_text().splitlines(), start=1)}


def line_of(path, text, after=None):
    """The number of the first line equal to ``text`` (after the line ``after``, if given)."""
    lines = lines_of(path)
    start = 0 if after is None else line_of(path, after)
    return next(n for n, t in sorted(lines.items()) if n > start and t == text)


@pytest.mark.parametrize(
    "text, metres, reference",
    [
        ("UNL FT", None, "AMSL"),
        ("UNL", None, "AMSL"),
        ("UNLTD", None, "AMSL"),
        ("2900AMSL FT", 2900 * FT, "AMSL"),
        ("2900 FT AMSL", 2900 * FT, "AMSL"),
        ("2900ft MSL", 2900 * FT, "AMSL"),
        ("2900FT  MSL", 2900 * FT, "AMSL"),
        ("1500 AGL", 1500 * FT, "AGL"),
        ("1500AGL FT", 1500 * FT, "AGL"),
        ("1000 ft GND", 1000 * FT, "AGL"),
        ("500F SFC", 500 * FT, "AGL"),
        ("FL65", 6500 * FT, "STD"),
        ("FL 65", 6500 * FT, "STD"),
        ("fl95", 9500 * FT, "STD"),
        ("SFC", 0.0, "AGL"),
        ("GND", 0.0, "AGL"),
        ("MSL", 0.0, "AMSL"),
        ("300 M MSL", 300.0, "AMSL"),
        ("300m AMSL", 300.0, "AMSL"),
        ("4500 MSL M", 4500.0, "AMSL"),
        ("800 m AGL", 800.0, "AGL"),
        ("1200", 1200 * FT, "AMSL"),
        ("2000 ft * a comment", 2000 * FT, "AMSL"),
    ],
)
def test_each_altitude_form_is_read_to_its_metres_and_reference(text, metres, reference):
    got = read_altitude(text)
    assert got[0] == (None if metres is None else pytest.approx(metres, abs=1e-3))
    assert got[1] == reference


@pytest.mark.parametrize(
    "text, why",
    [
        ("NOTAM", "NOTAM"),
        ("Notam", "NOTAM"),
        ("BCTA FT", "no altitude"),
        ("TMA", "no altitude"),
        ("-5m", "no altitude"),
        ("FL", "no altitude"),
        ("FL65 MSL", "no altitude"),
        ("1000 2000", "more than one"),
        ("1000 FT M", "more than one"),
    ],
)
def test_words_without_a_numeric_meaning_are_unreadable(text, why):
    with pytest.raises(Unreadable, match=why):
        read_altitude(text)


def test_a_gliding_file_reads_its_bands_from_every_form(rules):
    got = {f.name: f for f in read_database([GLIDING], rules).features}

    def band(name):
        f = got[name]
        refs = (f.properties["lower_reference"], f.properties["upper_reference"])
        return f.alt_min_m, f.alt_max_m, refs

    assert band("ALPHA R901 GND-2900AMSL") == (0.0, pytest.approx(2900 * FT), ("AGL", "AMSL"))
    assert band("BRAVO D902") == (
        pytest.approx(1500 * FT),
        pytest.approx(2900 * FT),
        ("AGL", "AMSL"),
    )
    assert band("CHARLIE P903") == (0.0, None, ("AGL", "AMSL"))
    assert band("DELTA D904") == (300.0, pytest.approx(2900 * FT), ("AMSL", "AMSL"))
    assert band("ECHO WAVE") == (
        pytest.approx(6500 * FT),
        pytest.approx(9500 * FT),
        ("STD", "STD"),
    )
    assert band("FOXTROT GLIDER SECTOR") == (pytest.approx(1000 * FT), 4500.0, ("AGL", "AMSL"))


def test_notam_and_unknown_limits_widen_a_keep_out_with_a_note(rules):
    notes = []
    features = openair.read_openair(GLIDING, rules, [], Counter(), notes)
    got = {f.name: f for f in features}
    golf, hotel = got["GOLF TRA (NOTAM)"], got["HOTEL CTA"]
    assert golf.kind == "keep_out" and hotel.kind == "keep_out"
    # a floor that cannot be read is the ground, a ceiling that cannot be read unlimited
    assert (golf.alt_min_m, golf.properties["lower_reference"]) == (0.0, "AGL")
    assert golf.alt_max_m is None
    assert (hotel.alt_min_m, hotel.properties["lower_reference"]) == (0.0, "AGL")
    assert hotel.alt_max_m == pytest.approx(6500 * FT)  # its FL65 ceiling is kept
    golf_al = line_of(GLIDING, "AL NOTAM")
    golf_ah = line_of(GLIDING, "AH NOTAM")
    hotel_al = line_of(GLIDING, "AL BCTA FT")
    assert len(notes) == 3, notes
    for name, line, what in [
        ("GOLF TRA (NOTAM)", golf_al, "AL 'NOTAM' is not read (the limit is set by NOTAM)"),
        ("GOLF TRA (NOTAM)", golf_ah, "AH 'NOTAM' is not read (the limit is set by NOTAM)"),
        ("HOTEL CTA", hotel_al, "AL 'BCTA FT' is not read"),
    ]:
        (note,) = [n for n in notes if f"({name}), line {line}: " in n]
        assert note.startswith(f"{GLIDING}: airspace ") and what in note and "\n" not in note
        limit = "the floor is taken as the ground" if "AL" in what else "the ceiling is taken"
        assert note.endswith(limit) or note.endswith(limit + " as unlimited")
    # the zones with readable limits have no note
    assert not any("ALPHA" in n or "CHARLIE" in n for n in notes)


def test_a_keep_in_is_not_widened(tmp_path):
    rules = parse_rules(
        {
            "rule": [
                {"category": "area", "kind": "keep_in", "tags": {"airspace:class": ["R"]}},
                {"category": "airspace", "kind": "keep_out", "tags": {"airspace:format": "*"}},
            ]
        }
    )
    with pytest.raises(InputError, match="keep-in's ceiling cannot be widened") as err:
        openair.read_openair(GLIDING, rules, [], Counter())
    message = str(err.value)
    assert "GOLF TRA (NOTAM)" in message and "HOTEL" not in message  # HOTEL is class C


def test_every_fault_of_a_file_is_reported_at_once(rules):
    with pytest.raises(InputErrors) as err:
        read_database([FAULTS], rules)
    message = str(err.value)
    head, *faults = message.splitlines()
    assert head == f"{FAULTS}: 4 problems:"
    expected = {
        "JULIET R912 TWO POINTS": (line_of(FAULTS, "AC R", "AH 2500ft MSL"), "at least 3"),
        "KILO D913 BAD MINUTES": (line_of(FAULTS, "DP 50:24:00 N 006:61:00 E"), "below 60"),
        "LIMA D914 NO CENTRE": (line_of(FAULTS, "DC 1.5"), "without a centre"),
        "MIKE R915 ON ONE LINE": (
            line_of(FAULTS, "AC R", "DC 1.5"),
            "on one line: not an area",
        ),
    }
    assert len(faults) == len(expected)
    for fault, (name, (line, what)) in zip(faults, expected.items()):
        assert fault.strip().startswith(f"{FAULTS}: airspace ") and f"({name})" in fault
        assert f"line {line}:" in fault and what in fault
    assert len({line for line, _ in expected.values()}) == 4  # four lines, one message
    assert "INDIA" not in message and "NOVEMBER" not in message
    assert [e.line for e in err.value.errors] == [line for line, _ in expected.values()]


def test_a_fence_file_read_lists_every_fault_too():
    with pytest.raises(InputErrors) as err:
        read_fence_file(FAULTS)
    assert len(err.value.errors) == 4


def test_invalid_airspaces_are_left_out_and_named_when_asked(rules):
    invalid, notes = [], []
    features = openair.read_openair(FAULTS, rules, [], Counter(), notes, invalid)
    assert sorted(f.name for f in features) == ["INDIA R911 GOOD", "NOVEMBER R916 GOOD"]
    assert [(e["airspace"], e["file"]) for e in invalid] == [
        ("JULIET R912 TWO POINTS", str(FAULTS)),
        ("KILO D913 BAD MINUTES", str(FAULTS)),
        ("LIMA D914 NO CENTRE", str(FAULTS)),
        ("MIKE R915 ON ONE LINE", str(FAULTS)),
    ]
    assert invalid[1]["line"] == line_of(FAULTS, "DP 50:24:00 N 006:61:00 E")
    assert "below 60" in invalid[1]["problem"]
    assert len(notes) == 1 and "NOVEMBER R916 GOOD" in notes[0]  # AH NOTAM, kept and widened


# -- the build: library and command line --------------------------------------------------


def fault_lines():
    """The lines the faults file's four faults are on, found in its text."""
    return [
        line_of(FAULTS, "AC R", "AH 2500ft MSL"),
        line_of(FAULTS, "DP 50:24:00 N 006:61:00 E"),
        line_of(FAULTS, "DC 1.5"),
        line_of(FAULTS, "AC R", "DC 1.5"),
    ]


def test_faults_of_several_files_are_reported_together(tmp_path, rules):
    other = tmp_path / "second.openair"
    other.write_bytes(FAULTS.read_bytes())
    with pytest.raises(InputErrors) as err:
        read_database([FAULTS, GLIDING, other], rules)
    assert [(e.path, e.line) for e in err.value.errors] == [
        *((str(FAULTS), n) for n in fault_lines()),
        *((str(other), n) for n in fault_lines()),
    ]


def test_the_library_skips_invalid_zones_when_asked(rules):
    from alphafence.fencing.outputs import build_meta
    from alphafence.fencing.pipeline import BuildOptions
    from alphafence.fencing.tiled import build_tiled
    from alphafence.zones.database import DatabaseStream

    db = read_database([FAULTS, GLIDING], rules, skip_invalid=True)
    assert [(z["airspace"], z["line"]) for z in db.invalid] == list(
        zip(
            [
                "JULIET R912 TWO POINTS",
                "KILO D913 BAD MINUTES",
                "LIMA D914 NO CENTRE",
                "MIKE R915 ON ONE LINE",
            ],
            fault_lines(),
        )
    )
    names = {f.name for f in db.features}
    assert "INDIA R911 GOOD" in names and "ALPHA R901 GND-2900AMSL" in names
    assert not any(z["airspace"] in names for z in db.invalid)
    assert len(db.notes) == 4  # GOLF's two limits, HOTEL's floor, NOVEMBER's ceiling

    stream = DatabaseStream([FAULTS, GLIDING], rules, skip_invalid=True)
    result = build_tiled(stream, rules, BuildOptions(), jobs=1)
    assert result.features == len(db.features)
    meta = build_meta(stream.database(), rules, BuildOptions())
    assert meta["skipped_invalid"] == db.invalid and meta["notes"] == db.notes

    with pytest.raises(InputErrors):  # without the option, the stream refuses them all
        list(DatabaseStream([FAULTS], rules).batches())


def test_build_without_skip_invalid_lists_every_fault_and_writes_nothing(tmp_path, capsys):
    from alphafence.cli import main

    out = tmp_path / "fences.geojson"
    plan = tmp_path / "fences.plan"
    code = main(["build", str(FAULTS), str(GLIDING), "-o", str(out), "--plan", str(plan)])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert lines[0] == f"alphafence build: error: {FAULTS}: 4 problems:"
    for line, n in zip(lines[1:5], fault_lines()):
        assert line.startswith(f"  {FAULTS}: airspace ") and f", line {n}: " in line
    assert "--skip-invalid" in lines[5] and len(lines) == 6
    assert list(tmp_path.iterdir()) == []  # no output, no temporary file


def test_build_with_skip_invalid_names_the_zones_left_out(tmp_path, capsys):
    import json

    from alphafence.cli import main

    out = tmp_path / "fences.geojson"
    code = main(["build", str(FAULTS), str(GLIDING), "-o", str(out), "--skip-invalid"])
    captured = capsys.readouterr()
    assert code == 0
    said = " ".join(captured.err.split())  # the console wraps long notes
    for name, line in zip(
        [
            "JULIET R912 TWO POINTS",
            "KILO D913 BAD MINUTES",
            "LIMA D914 NO CENTRE",
            "MIKE R915 ON ONE LINE",
        ],
        fault_lines(),
    ):
        assert f"left out (--skip-invalid): {FAULTS}: airspace '{name}', line {line}: " in said
    assert "AH 'NOTAM' is not read" in said and "the ceiling is taken as unlimited" in said
    doc = json.loads(out.read_text())
    left_out = doc["alphafence"]["skipped_invalid"]
    assert [(z["file"], z["line"]) for z in left_out] == [(str(FAULTS), n) for n in fault_lines()]
    assert left_out[0]["airspace"] == "JULIET R912 TWO POINTS"
    assert "at least 3" in left_out[0]["problem"]
    assert any("GOLF TRA (NOTAM)" in n for n in doc["alphafence"]["notes"])
    fenced = {f["properties"]["name"] for f in doc["features"]}
    assert "INDIA R911 GOOD" in fenced and "GOLF TRA (NOTAM)" in fenced
    assert not fenced & {z["airspace"] for z in left_out}
