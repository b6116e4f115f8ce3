"""How large a map page stays usable: N small synthetic fences (hexagons of 20-60 m, a keep-out
fence and its warning layer each, spread over a country-sized box) written with --map's code,
opened in Debian's headless chromium, timed to the first drawn frame, then a pan and a zoom.

    python -m bench.webmap_bench --fences 100000 200000

Prints one line per size: fences, page MB, seconds to write it, seconds to the first frame,
seconds for a zoom-in and a pan to be drawn.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import shapely

ROOT = Path(__file__).resolve().parents[1]


def synthetic_fences(n, seed=1):
    """``n`` fence records: ``n // 2`` keep-out hexagons and their warning layers, in a
    4 x 3 degree box (about Switzerland's size)."""
    from alphafence.fencefiles.fence_geojson import FenceRecord

    rng = np.random.default_rng(seed)
    sites = n // 2
    lon = rng.uniform(6.0, 10.0, sites)
    lat = rng.uniform(45.8, 48.8, sites)
    r = rng.uniform(20.0, 60.0, sites)
    angles = np.linspace(0, 2 * math.pi, 7)[:-1]
    records = []
    for k in range(sites):
        dlat = r[k] / 111_320.0  # the hexagon's size only: the fences' shapes are not measured
        dlon = dlat / math.cos(math.radians(lat[k]))
        ring = np.column_stack([lon[k] + dlon * np.cos(angles), lat[k] + dlat * np.sin(angles)])
        outer = ring * [1, 1] + (ring - [lon[k], lat[k]]) * 0.6
        props = {"site_id": f"synthetic/{k}", "name": f"site {k}", "category": "synthetic",
                 "margin_m": 10.0, "vertices": 6, "area_m2": 2.6 * r[k] ** 2, "sources": [k]}  # fmt: skip
        records.append(FenceRecord(props["site_id"], "keep_out", shapely.Polygon(ring),
                                   properties={**props, "kind": "keep_out"}))  # fmt: skip
        records.append(FenceRecord(props["site_id"], "warning", shapely.Polygon(outer),
                                   properties={**props, "kind": "warning"}))  # fmt: skip
    return records


def _until(driver, script, timeout=600):
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(driver, timeout, poll_frequency=0.05).until(lambda d: d.execute_script(script))


def measure(n, folder, driver):
    """Write and open a page of ``n`` fences; the numbers of one line."""
    from alphafence.plots.webmap import fence_layers, write_map

    records = synthetic_fences(n)
    path = Path(folder) / f"fences-{n}.html"
    t0 = time.perf_counter()
    write_map(path, f"{n} synthetic fences", fence_layers(records))
    write_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    driver.get(path.as_uri())
    _until(driver, "return window.afReady")
    first_s = time.perf_counter() - t0
    frame = (
        "window.afDone = false; window.afMap.once('moveend', function () {"
        " requestAnimationFrame(function () { requestAnimationFrame(function () {"
        " window.afDone = true; }); }); });"
    )
    t0 = time.perf_counter()
    driver.execute_script(frame + "window.afMap.setView([47.3, 8.5], 12, {animate: false});")
    _until(driver, "return window.afDone")
    zoom_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    driver.execute_script(frame + "window.afMap.panBy([400, 300], {animate: false});")
    _until(driver, "return window.afDone")
    pan_s = time.perf_counter() - t0
    shown = driver.execute_script(
        "var n = 0; for (var k in window.afLayers) n += window.afLayers[k].getLayers().length;"
        "return n;"
    )
    assert shown == len(records), (shown, len(records))
    mb = path.stat().st_size / 1e6
    return f"{n:>8,} fences  {mb:7.1f} MB  write {write_s:6.1f} s  first frame {first_s:6.1f} s  zoom {zoom_s:5.2f} s  pan {pan_s:5.2f} s"  # fmt: skip


def main(argv=None):
    """Measure the sizes asked (default 100,000 fences)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fences", type=int, nargs="+", default=[100_000])
    args = p.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from tests.browser import start

    folder = tempfile.mkdtemp(prefix="alphafence-webmap-bench-")
    driver, profile = start()
    driver.set_page_load_timeout(900)
    try:
        for n in args.fences:
            print(measure(n, folder, driver), flush=True)
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
