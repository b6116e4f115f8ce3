"""``make mutation``'s rules (tests/mutation): a survivor not listed fails the run, a listed one
passes, a listed one killed since is reported; CI picks the targets whose module changed since
the scores were recorded; every target names a module and tests that exist, and every listed
survivor says why it is harmless."""

from __future__ import annotations

from pathlib import Path

from tests.mutation.__main__ import (
    KIT,
    ROOT,
    changed_targets,
    judge,
    module_hash,
    survivors_listed,
    targets,
)

MODULE = "alphafence/vehicle/fast_frames.py"
LISTED = [{"module": MODULE, "function": "x__crc", "removed": "a  = 1", "added": "a = 2",
           "why": "equivalent"}]  # fmt: skip


def result(*survivors):
    return {"module": MODULE, "survivors": [("name", *s) for s in survivors]}


def test_an_unlisted_survivor_fails_and_a_listed_one_passes():
    unlisted, stale = judge(result(("x__crc", "a = 1", "a = 2")), LISTED)
    assert (unlisted, stale) == ([], [])  # spaces do not matter
    unlisted, stale = judge(result(("x__crc", "a = 1", "a = 3")), LISTED)
    assert [u[1:] for u in unlisted] == [("x__crc", "a = 1", "a = 3")]
    assert stale == LISTED  # and the listed one no longer survives


def test_a_listed_survivor_of_another_module_is_not_stale():
    other = [dict(LISTED[0], module="alphafence/geo/lonlat.py")]
    assert judge(result(), other) == ([], [])


def test_ci_runs_the_targets_whose_module_changed(tmp_path, monkeypatch):
    import json

    from tests.mutation import __main__ as driver

    every = targets()
    monkeypatch.setattr(driver, "HERE", tmp_path)
    assert changed_targets(every) == every  # nothing recorded: all
    recorded = {t["module"]: module_hash(t["module"]) for t in every}
    recorded[MODULE] = "0" * 16  # as if fast_frames.py had changed since
    (tmp_path / "scores.json").write_text(json.dumps({"modules": recorded, "scores": {}}))
    assert [t["module"] for t in changed_targets(every)] == [MODULE]


def test_the_targets_and_survivors_name_what_exists():
    for t in targets():
        assert (KIT / t["module"]).is_file(), t
        assert t["functions"] and all((ROOT / p).is_file() for p in t["tests"]), t
    for s in survivors_listed():
        assert (KIT / s["module"]).is_file() and s["why"].strip(), s
        assert s["removed"] in " | ".join(Path(KIT / s["module"]).read_text().split("\n")) or (
            "|" in s["removed"]
        ), s
