import json
import os
from pathlib import Path

import pytest
from hypothesis import settings

from .ci_env import hypothesis_profile, under_ci

pytest_plugins = ["tests.sitl_fixtures", "tests.live_servers", "tests.browser"]

# CI runs the property tests on a fixed seed so a run is reproducible; locally each run
# explores new examples (and replays any failure hypothesis has saved).
settings.register_profile("ci", derandomize=True, deadline=None)
if hypothesis_profile():
    settings.load_profile(hypothesis_profile())

# A checkout with ../shared beside it (CI's layout) has a prebuilt copter SITL there: the SITL
# tests use it when no other binary is found ($ARDUPILOT_SITL, $ARDUPILOT_HOME, ~/ardupilot,
# PATH), by the same search the kit makes. $ALPHAFENCE_SHARED moves ../shared (its SITLs and
# its data), for the test that hides them.
SHARED_ROOT = Path(
    os.environ.get("ALPHAFENCE_SHARED") or Path(__file__).resolve().parents[2] / "shared"
)
SHARED_SITL = SHARED_ROOT / "ardupilot-sitl"


def _use_shared_sitl():
    from alphafence.sitl.find import find_sitl_binary

    if find_sitl_binary() is None and (SHARED_SITL / "build/sitl/bin/arducopter").is_file():
        os.environ["ARDUPILOT_HOME"] = str(SHARED_SITL)


_use_shared_sitl()

# The same for PX4: ../shared/px4-sitl (a headless SIH build) when $PX4_SITL and
# ~/PX4-Autopilot have none.
SHARED_PX4 = SHARED_ROOT / "px4-sitl"


def _use_shared_px4():
    from alphafence.sitl.px4 import find_px4

    if find_px4() is None and (SHARED_PX4 / "bin/px4").is_file():
        os.environ["PX4_SITL"] = str(SHARED_PX4)


_use_shared_px4()


# Under CI a skip is a failure, whatever its reason and whenever it happens (at collection,
# setup, in the test or at teardown): a missing SITL, browser, selenium, MAVSDK, socat,
# PostgreSQL, data file or declared dependency cannot pass CI by skipping. A test whose skip is
# no missing part (a check that does not apply to an older pymavlink, say) says so with
# ``@pytest.mark.may_skip("why")``; tests/test_ci_skips.py holds the rule to a run that hides
# every part.
CI_SKIP = "CI=true, so this skip is a failure"


def _skip_reason(report):
    longrepr = report.longrepr
    reason = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
    return reason.removeprefix("Skipped: ")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if not (report.skipped and under_ci()) or hasattr(report, "wasxfail"):
        return
    if item.get_closest_marker("may_skip") is not None:
        return
    report.outcome = "failed"
    report.longrepr = f"{CI_SKIP} (a missing real part or dependency): {_skip_reason(report)}"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    report = outcome.get_result()
    if report.skipped and under_ci():
        report.outcome = "failed"
        report.longrepr = f"{CI_SKIP} (at collection): {_skip_reason(report)}"


# pyproject's timeout (900 s) bounds every test; one that drives SITL (start-up, flights at
# speedup 1) gets this instead, unless it sets its own @pytest.mark.timeout
SITL_TIMEOUT_S = 1800


def pytest_collection_modifyitems(config, items):
    """Give each test marked ``sitl`` without a timeout of its own SITL_TIMEOUT_S (with
    pytest-timeout installed: pyproject's dev extra)."""
    if not config.pluginmanager.hasplugin("timeout"):
        return
    for item in items:
        if item.get_closest_marker("sitl") and not item.get_closest_marker("timeout"):
            item.add_marker(pytest.mark.timeout(SITL_TIMEOUT_S))


ROOT = Path(__file__).resolve().parents[1]
SHARED = SHARED_ROOT / "data" / "osm"
MALTA = SHARED / "malta-2018-08-27.osm.pbf"
MONACO = SHARED / "monaco-2016-03.osm.pbf"


@pytest.fixture(scope="session")
def malta():
    if not MALTA.is_file():
        pytest.skip(f"Malta extract not found at {MALTA} (../shared beside the checkout)")
    return MALTA


@pytest.fixture(scope="session")
def monaco():
    if not MONACO.is_file():
        pytest.skip(f"Monaco extract not found at {MONACO}")
    return MONACO


@pytest.fixture(scope="module")
def demo_fences(tmp_path_factory):
    """The demo scene's fences, built (a fence GeoJSON's path)."""
    from alphafence.cli import main
    from alphafence.cli.demo import scene_path

    out = tmp_path_factory.mktemp("fences") / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(out), "-q"]) == 0
    return out


@pytest.fixture(scope="session")
def rules():
    from alphafence.zones.rules import load_rules

    return load_rules()


@pytest.fixture(scope="session")
def malta_db(malta, rules):
    from alphafence.zones.database import read_database

    return read_database([malta], rules)


@pytest.fixture
def write_json(tmp_path):
    def write(name, doc):
        path = tmp_path / name
        path.write_text(json.dumps(doc))
        return path

    return write


@pytest.fixture(params=["pymavlink", "mavsdk"])
def link(request, monkeypatch):
    """Each vehicle link in turn (``$ALPHAFENCE_LINK``, which ``open_vehicle`` follows); a link
    that is not installed here (MAVSDK 4 on 32-bit ARM) is skipped."""
    from alphafence.vehicle.link import NoLinkError, choose_link

    try:
        choose_link(request.param)
    except NoLinkError as exc:
        pytest.skip(str(exc))
    monkeypatch.setenv("ALPHAFENCE_LINK", request.param)
    return request.param


# How many examples reached each as-read assertion, per method (or profile) and size class:
# the property tests call ``checked(...)``; each worker appends to one file, and the run's
# summary counts them (a class never reached shows as 0).
COUNTS_ENV = "ALPHAFENCE_CHECK_COUNTS"


def pytest_configure(config):
    if not hasattr(config, "workerinput") and COUNTS_ENV not in os.environ:
        import tempfile

        fd, path = tempfile.mkstemp(prefix="alphafence-checks-", suffix=".txt")
        os.close(fd)
        os.environ[COUNTS_ENV] = path
        config._alphafence_counts = path


def checked(test, kind, size_km):
    """Count one example that reached ``test``'s assertions for ``kind`` and size class."""
    path = os.environ.get(COUNTS_ENV)
    if path:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(f"{test}\t{kind}\t{size_km}\n")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    path = getattr(config, "_alphafence_counts", None)
    if not path or not os.path.exists(path):
        return
    import collections

    with open(path, encoding="utf-8") as fh:
        rows = collections.Counter(
            tuple(line.rstrip("\n").split("\t")) for line in fh if line.strip()
        )
    os.unlink(path)
    if not rows:
        return
    terminalreporter.section("as-read examples checked (per method or profile, size class)")
    for test in sorted({r[0] for r in rows}):
        kinds = sorted({r[1] for r in rows if r[0] == test})
        sizes = sorted({r[2] for r in rows if r[0] == test}, key=float)
        cells = "  ".join(
            f"{k}: " + "/".join(str(rows[(test, k, z)]) for z in sizes) for k in kinds
        )
        terminalreporter.write_line(f"{test} (km {'/'.join(sizes)}): {cells}")
