"""Under ``CI=true`` no test passes by skipping: a test whose real part or declared dependency
is missing fails, whatever its skip says and whenever it skips (at collection, in a fixture, in
the test). Without CI the user gets the one-line skip.

Each route is taken by a run of this suite's own tests with the part really hidden: no SITL
(no $ARDUPILOT_*, $PX4_SITL, ~/ardupilot or ~/PX4-Autopilot, ../shared moved to an empty
folder), no Chromium (its paths moved), no selenium, MAVSDK or pyulog (packages on PYTHONPATH
that fail to import), no socat or make (a PATH of the venv's commands only), no pygeoapi, no
PostgreSQL, no data (the same empty ../shared)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from .ci_env import hypothesis_profile, under_ci

ROOT = Path(__file__).resolve().parents[1]

# one test per route a missing part takes to a skip
EVERY_PART = {
    "ArduPilot SITL": "tests/test_upload_sitl.py::test_fence_parameters_applied[pymavlink-sitl0]",
    "PX4 SITL": "tests/test_px4_sitl.py::"
    "test_the_budget_is_accepted_and_one_over_refused_with_the_old_fence_kept[pymavlink]",
    "Chromium": "tests/test_webmap_browser.py::test_an_mbtiles_basemap_is_drawn_from_the_page_itself",
    "socat": "tests/test_serial_link.py::test_cli_download_over_a_serial_port",
    "pygeoapi": "tests/test_live_build.py::"
    "test_the_offline_copy_records_the_source_and_fences_each_zone",
    "the Malta extract": "tests/test_build_jobs.py::"
    "test_a_small_database_starts_no_worker_even_with_many_cores",
    "make": "tests/test_make_demo.py::test_make_demo_says_what_it_installs_before_pip_runs",
    "MAVSDK": "tests/test_param_presets.py::"
    "test_a_preset_for_another_vehicle_is_refused_before_anything_is_sent[mavsdk]",
    "pyulog (at collection)": "tests/test_ulog.py",
}
# with the rest there: the routes another missing part would hide
ONE_PART = {
    "selenium": EVERY_PART["Chromium"],
    "PostgreSQL": EVERY_PART["pygeoapi"],
    "SITL blocks of a docs page": "tests/test_docs_commands.py::test_the_pages_commands_run[sitl.md]",
}


def hidden_env(tmp_path, ci, parts):
    """The environment of a run with ``parts`` hidden (a set of "sitl", "chromium",
    "modules", "path", "pygeoapi", "postgres", "data")."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("ARDUPILOT_", "PX4_", "PYTEST_", "ALPHAFENCE_"))}  # fmt: skip
    env["CI"] = "true" if ci else ""
    env["HOME"] = str(tmp_path / "home")
    (tmp_path / "home").mkdir(exist_ok=True)
    empty = tmp_path / "empty"
    empty.mkdir(exist_ok=True)
    if "data" in parts:
        env["ALPHAFENCE_SHARED"] = str(empty)  # no SITL, no PX4, no extracts
    elif "sitl" in parts:  # the extracts alone
        shared = tmp_path / "shared"
        (shared / "data").mkdir(parents=True, exist_ok=True)
        real = Path(os.environ.get("ALPHAFENCE_SHARED") or ROOT.parent / "shared")
        if not (shared / "data" / "osm").exists():
            (shared / "data" / "osm").symlink_to(real / "data" / "osm")
        env["ALPHAFENCE_SHARED"] = str(shared)
    if "sitl" not in parts:
        env["HOME"] = os.environ.get("HOME", env["HOME"])
    if "chromium" in parts:
        env["ALPHAFENCE_CHROMIUM"] = env["ALPHAFENCE_CHROMEDRIVER"] = str(empty / "chromium")
    if "modules" in parts:
        blockers = tmp_path / "blockers"
        for name in parts["modules"]:
            (blockers / name).mkdir(parents=True, exist_ok=True)
            (blockers / name / "__init__.py").write_text(
                f"raise ModuleNotFoundError('{name} hidden by tests/test_ci_skips.py', "
                f"name='{name}')\n"
            )
        env["PYTHONPATH"] = str(blockers)
    if "path" in parts:
        env["PATH"] = str(Path(sys.executable).parent)  # no socat, no make
    if "pygeoapi" in parts:
        env["ALPHAFENCE_PYGEOAPI"] = str(empty / "pygeoapi")
    if "postgres" in parts:
        env["ALPHAFENCE_HIDE_POSTGIS"] = "1"
    return env


PROBE = """
import json, os

def _write(nodeid, when, outcome):
    with open(os.environ["ALPHAFENCE_PROBE"], "a") as fh:
        fh.write(json.dumps([nodeid, when, outcome]) + "\\n")

def pytest_runtest_logreport(report):
    _write(report.nodeid, report.when, report.outcome)

def pytest_collectreport(report):
    if report.nodeid.endswith(".py"):
        _write(report.nodeid, "collect", report.outcome)
"""


def outcomes(tmp_path, ci, parts, tests):
    """What became of each test (or module) in a run with ``parts`` hidden: "failed" if any
    phase failed (collection included), else "skipped", "passed", or "absent"."""
    import json

    probe = tmp_path / "probe"
    probe.mkdir(exist_ok=True)
    (probe / "skip_probe.py").write_text(PROBE)
    log = tmp_path / f"outcomes-{int(ci)}.jsonl"
    env = hidden_env(tmp_path, ci, parts)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("PYTHONPATH"), str(probe)) if p)
    env["ALPHAFENCE_PROBE"] = str(log)
    argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "no:xdist",
            "-p", "skip_probe", "-q", "-rA", "--continue-on-collection-errors", *tests]  # fmt: skip
    run = subprocess.run(argv, cwd=ROOT, env=env, text=True, capture_output=True, timeout=900)
    rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    said = {}
    for test in tests:
        seen = {
            outcome for node, _, outcome in rows if node == test or node.startswith(test + "::")
        }
        said[test] = (
            "failed" if "failed" in seen
            else "skipped" if "skipped" in seen
            else "passed" if "passed" in seen
            else "absent"
        )  # fmt: skip
    return said, run


EVERYTHING = {"sitl": 1, "chromium": 1, "path": 1, "pygeoapi": 1, "postgres": 1, "data": 1,
              "modules": ("selenium", "mavsdk", "pyulog")}  # fmt: skip


def test_every_hidden_part_fails_under_ci(tmp_path):
    tests = list(EVERY_PART.values())
    said, run = outcomes(tmp_path, True, EVERYTHING, tests)
    assert said == dict.fromkeys(tests, "failed"), run.stdout[-4000:]
    assert "CI=true, so this skip is a failure" in run.stdout
    assert "ERROR tests/test_ulog.py" in run.stdout  # the module-level importorskip
    assert "chromium" in run.stdout and "socat" in run.stdout and "no make" in run.stdout


def test_every_hidden_part_is_a_one_line_skip_without_ci(tmp_path):
    tests = list(EVERY_PART.values())
    said, run = outcomes(tmp_path, False, EVERYTHING, tests)
    assert said == dict.fromkeys(tests, "skipped"), run.stdout[-4000:]
    assert run.returncode == 0, run.stdout[-4000:]


def test_a_part_hidden_behind_the_others_fails_under_ci(tmp_path):
    tests = list(ONE_PART.values())
    parts = {"sitl": 1, "postgres": 1, "modules": ("selenium",)}
    said, run = outcomes(tmp_path, True, parts, tests)
    assert said == dict.fromkeys(tests, "failed"), run.stdout[-4000:]
    assert "needs SITL" in run.stdout and "PostgreSQL" in run.stdout
    assert "selenium" in run.stdout


@pytest.mark.parametrize(
    ("value", "on"),
    [("true", True), ("TRUE", True), (" 1 ", True), ("yes", True), ("on", True),
     ("", False), ("false", False), ("0", False), ("no", False), ("off", False),
     ("maybe", False)],
)  # fmt: skip
def test_ci_is_read_one_way_for_the_skip_rule_and_hypothesis(value, on):
    assert under_ci({"CI": value}) is on
    assert (hypothesis_profile({"CI": value}) == "ci") is on
    # qemu's runs ask for the profile alone, without CI's skip rule
    assert hypothesis_profile({"CI": value, "ALPHAFENCE_HYPOTHESIS_PROFILE": "ci"}) == "ci"
