"""The interactive maps in a real browser (Debian's headless chromium): the Malta build's map
opens with no network and draws every fence, a click on a fence shows its properties, a
post-flight map shows the track, the breach and the alerts with their UTC times; and --map
refuses a path it cannot write before any work."""

from __future__ import annotations

import json
import os

import pytest
import shapely

from alphafence.cli import main
from tests.browser import browser, layer_counts, open_map, requests_made  # noqa: F401

pytestmark = pytest.mark.browser

FENCE_LAYERS = {"keep_out": "keep-out fences", "warning": "warning layers", "keep_in": "keep-in fences"}  # fmt: skip


@pytest.fixture(scope="module")
def malta_map(malta, tmp_path_factory):
    out = tmp_path_factory.mktemp("malta-map")
    code = main(["build", str(malta), "-o", str(out / "f.geojson"), "--map", str(out / "m.html"), "-q"])  # fmt: skip
    assert code == 0
    return out / "f.geojson", out / "m.html"


def _severe(driver):
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def test_the_malta_map_opens_with_no_network_and_draws_every_fence(browser, malta_map):  # noqa: F811
    geojson, html = malta_map
    open_map(browser, html)
    assert requests_made(browser) == []  # nothing fetched after the file itself
    assert _severe(browser) == []
    features = json.loads(geojson.read_text())["features"]
    wanted = {}
    for f in features:
        layer = FENCE_LAYERS[f["properties"]["kind"]]
        wanted[layer] = wanted.get(layer, 0) + 1
    counts = layer_counts(browser)
    assert {k: counts.get(k) for k in wanted} == wanted
    assert sum(counts[k] for k in wanted) == len(features)
    # the legend lists only the layers drawn
    legend = browser.execute_script("return document.querySelector('.af-legend').innerText")
    assert "keep-out fence" in legend and "keep-in" not in legend
    # the grid labels say where on Earth this is
    labels = browser.execute_script(
        "return Array.from(document.querySelectorAll('.af-grid-label')).map(e => e.innerText)"
    )
    assert any(t.endswith("°N") and t.startswith("35.") for t in labels)
    shots = os.environ.get("ALPHAFENCE_SHOTS")  # the docs' picture: make this run with it set
    if shots:
        browser.execute_script(
            "var l = window.afLayers['keep-out fences'].getLayers().reduce(function (a, b) {"
            " return a.getBounds().getNorthEast().distanceTo(a.getBounds().getSouthWest()) >"
            " b.getBounds().getNorthEast().distanceTo(b.getBounds().getSouthWest()) ? a : b; });"
            "l.fire('click', {latlng: l.getBounds().getCenter()}, true);"
        )
        from selenium.webdriver.support.ui import WebDriverWait

        WebDriverWait(browser, 30).until(
            lambda d: d.execute_script(
                "var p = document.querySelector('.leaflet-popup');"
                "return p && getComputedStyle(p).opacity === '1';"
            )
        )  # faded in
        browser.save_screenshot(os.path.join(shots, "map-malta.png"))


def _lonely_point(features, kind="keep_out"):
    """A named fence of ``kind`` and a point inside it and inside no other fence of that kind."""
    shapes = [shapely.geometry.shape(f["geometry"]) for f in features]
    for f, g in sorted(zip(features, shapes), key=lambda fg: -fg[1].area):
        p = f["properties"]
        if p["kind"] != kind or not p.get("name"):
            continue
        at = g.representative_point()
        others = [
            h for h, o in zip(shapes, features) if o is not f and o["properties"]["kind"] == kind
        ]
        if not any(h.contains(at) for h in others):
            return p, at
    raise AssertionError("no lonely named fence")


def test_a_click_on_a_fence_shows_its_properties(browser, malta_map):  # noqa: F811
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    geojson, html = malta_map
    open_map(browser, html)
    props, at = _lonely_point(json.loads(geojson.read_text())["features"])
    browser.execute_script(
        "window.afMap.setView([arguments[0], arguments[1]], 17, {animate: false});", at.y, at.x
    )
    xy = browser.execute_script(
        "var p = window.afMap.latLngToContainerPoint([arguments[0], arguments[1]]);"
        "return [p.x, p.y];",
        at.y,
        at.x,
    )
    element = browser.find_element(By.ID, "map")
    size = element.size
    ActionChains(browser).move_to_element_with_offset(
        element, xy[0] - size["width"] / 2, xy[1] - size["height"] / 2
    ).click().perform()
    # the popup's text as the page lays it out (fading in, it is not yet "visible" to
    # WebDriver's own .text)
    text = (
        WebDriverWait(browser, 30)
        .until(
            lambda d: d.execute_script(
                "var p = document.querySelector('.leaflet-popup-content');"
                "return p && p.innerText.trim();"
            )
        )
        .replace("\t", " ")
    )
    assert props["name"] in text and props["site_id"] in text
    assert props["category"] in text and "keep-out" in text
    assert f"{props['margin_m']:g} m" in text
    assert f"\nvertices {props['vertices']}\n" in f"\n{text}\n"
    assert f"{props['area_m2']:,.0f} m²" in text
    assert str(props["sources"][0]) in text
    assert "all altitudes" in text or " m " in text  # the band, with its references


def test_a_flight_map_shows_the_track_the_breach_and_the_alerts(browser, tmp_path, capsys):  # noqa: F811
    pytest.importorskip("pymavlink")
    from tests.test_check_flight import WALL, feature, fence_file, track, write_tlog

    fences = fence_file(
        tmp_path,
        feature("prison/1", "keep_out", WALL),
        feature("prison/1", "warning", WALL.buffer(30)),
    )
    log = write_tlog(tmp_path / "f.tlog", track([(0, 1), (0, 500)]))
    html = tmp_path / "flight.html"
    assert main(["check-flight", str(log), "--fences", str(fences), "--map", str(html)]) == 1
    assert main(["check-flight", str(log), "--fences", str(fences), "--json"]) == 1
    capsys.readouterr()
    open_map(browser, html)
    assert requests_made(browser) == []
    counts = layer_counts(browser)
    assert counts["flight track"] >= 3  # the segments and its two ends
    assert counts["keep-out fences"] == 1
    popups = browser.execute_script(
        "var out = {}; ['breaches', 'events'].forEach(function (k) {"
        " out[k] = window.afLayers[k].getLayers().map(function (l) {"
        "  return l.feature.properties.popup; }); }); return out;"
    )
    report = _report(log, fences)
    (hit,) = [i for i in report["incursions"] if i["kind"] == "keep_out"]
    assert ["UTC", hit["in"]] in [row for p in popups["breaches"] for row in p]
    whens = sorted(row[1] for p in popups["events"] for row in p if row[0] == "UTC")
    assert whens == sorted(a["when"] for a in report["alerts"]) and whens


def _report(log, fences):
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "alphafence", "check-flight", str(log), "--fences", str(fences), "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    return json.loads(out.stdout)


def test_an_unwritable_map_is_refused_in_one_line_before_any_work(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    target = blocker / "m.html"
    # the database does not exist: refusing --map first shows no work was started
    code = main(["build", str(tmp_path / "missing.osm.pbf"), "-o", str(tmp_path / "f.geojson"),
                 "--map", str(target)])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "--map" in err and "not a folder" in err
    assert not (tmp_path / "f.geojson").exists()
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        code = main(["build", str(tmp_path / "x.pbf"), "-o", "f.geojson", "--map", str(ro / "m.html")])  # fmt: skip
        assert code == 2 and "cannot write" in capsys.readouterr().err


def test_an_mbtiles_basemap_is_drawn_from_the_page_itself(browser, tmp_path):  # noqa: F811
    import io

    from PIL import Image

    from alphafence.plots.mbtiles import tile_range
    from tests.test_webmap_page import _mbtiles

    buf = io.BytesIO()
    Image.new("RGB", (256, 256), (200, 220, 255)).save(buf, format="PNG")
    ring = [[14.50, 35.89], [14.52, 35.89], [14.52, 35.91], [14.50, 35.89]]
    doc = {"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
           "properties": {"site_id": "prison/1", "kind": "keep_out", "name": "Kordin"}}]}  # fmt: skip
    fences = tmp_path / "f.geojson"
    fences.write_text(json.dumps(doc))
    tiles = []
    for z in (12, 13, 14):
        x0, x1, y0, y1 = tile_range([[35.89, 14.50], [35.91, 14.52]], z)
        tiles += [(z, x, 2**z - 1 - y, buf.getvalue()) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]  # fmt: skip
    base = _mbtiles(tmp_path / "base.mbtiles", tiles)
    html = tmp_path / "m.html"
    code = main(["compile", str(fences), "--bbox", "14.49,35.88,14.53,35.92", "-o", str(tmp_path / "o.plan"), "--map", str(html),
                 "--tiles", str(base)])  # fmt: skip
    assert code == 0
    open_map(browser, html)
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            "return Array.from(document.querySelectorAll('.leaflet-tile')).some("
            "function (t) { return t.src && t.src.indexOf('data:image/png') === 0 && t.complete; });"
        )
    )
    assert [u for u in requests_made(browser) if not u.startswith("data:")] == []
    assert "© sample" in browser.execute_script(
        "return document.querySelector('.leaflet-control-attribution').innerText"
    )
