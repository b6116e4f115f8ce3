import json
import os
from pathlib import Path

import pytest
from hypothesis import settings

pytest_plugins = ["tests.sitl_fixtures"]

# CI runs the property tests on a fixed seed so a run is reproducible; locally each run
# explores new examples (and replays any failure hypothesis has saved).
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

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
SHARED = ROOT.parent / "shared" / "data" / "osm"
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


@pytest.fixture(scope="session")
def rules():
    from alphafence.formats.rules import load_rules

    return load_rules()


@pytest.fixture(scope="session")
def malta_db(malta, rules):
    from alphafence.formats.database import read_database

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
