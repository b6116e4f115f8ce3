"""Headless Chromium (Debian's ``chromium`` and ``chromium-driver``) through Selenium, for tests
of the HTML maps in a real browser.

Use it with ``from tests.browser import browser  # noqa: F401`` in a test module. Nothing is
downloaded: the driver and the browser are the system's, given by path (Selenium Manager is
never asked), and every network request the browser would make goes to a closed port, so a
page that needs the network shows it. Without them the tests skip with one line naming the
packages.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

# Debian's paths ($ALPHAFENCE_CHROMIUM and $ALPHAFENCE_CHROMEDRIVER move them, for the test
# that hides them)
CHROMIUM = os.environ.get("ALPHAFENCE_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("ALPHAFENCE_CHROMEDRIVER", "/usr/bin/chromedriver")
MISSING = "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"

FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--disable-extensions",
    "--no-first-run",
    "--no-default-browser-check",
    # no request leaves the browser: names resolve nowhere, and any proxyable URL would go
    # to the discard port of this machine
    "--host-resolver-rules=MAP * ~NOTFOUND",
    "--proxy-server=127.0.0.1:9",
)


def start(window=(1000, 800), loopback=False):
    """A new headless Chromium WebDriver with its own profile folder, or a skip.

    ``loopback=True`` lets it reach 127.0.0.1 (a server the test runs, such as the live
    map's); every other name still resolves nowhere.

    Returns
    -------
    (selenium.webdriver.Chrome, str)
        The driver and the profile folder (remove it after ``driver.quit()``).
    """
    if not (Path(CHROMIUM).is_file() and Path(CHROMEDRIVER).is_file()):
        pytest.skip(MISSING)
    webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (the dev extra)")
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="alphafence-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        if loopback and flag.startswith("--host-resolver-rules="):
            flag += ", EXCLUDE 127.0.0.1"
        options.add_argument(flag)
    options.add_argument(f"--window-size={window[0]},{window[1]}")
    options.add_argument(f"--user-data-dir={profile}")
    driver = webdriver.Chrome(options=options, service=Service(executable_path=CHROMEDRIVER))
    driver.set_page_load_timeout(120)
    driver.set_script_timeout(120)
    return driver, profile


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium WebDriver shared by a module's tests (skips without Chromium)."""
    driver, profile = start()
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def open_map(driver, path, timeout=120):
    """Load the map page at ``path`` (a file:// URL) and wait until its first frame is drawn.

    Returns
    -------
    float
        ``window.afReady``: milliseconds from the start of navigation to the first frame.
    """
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(Path(path).resolve().as_uri())
    WebDriverWait(driver, timeout).until(lambda d: d.execute_script("return window.afReady"))
    return driver.execute_script("return window.afReady")


def requests_made(driver):
    """The URLs the page fetched after the document itself (resource timing entries)."""
    return driver.execute_script(
        "return performance.getEntriesByType('resource').map(function (e) { return e.name; })"
    )


def layer_counts(driver):
    """``{layer name: shapes drawn}``, counted through Leaflet's API."""
    return driver.execute_script(
        "var out = {}; Object.keys(window.afLayers).forEach(function (k) {"
        " out[k] = window.afLayers[k].getLayers().length; }); return out;"
    )


@pytest.fixture(scope="module")
def local_browser():
    """Headless Chromium that may reach 127.0.0.1 (a live map's server), nothing else."""
    driver, profile = start(loopback=True)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
