"""The live map shows a live source's zones as they arrive: the fences near the vehicle are
gathered again when the source's zones change them, each new zone's fence says which zone it is
and its time window, and the page gets the zone's event with its window and source. Real
pygeoapi over PostGIS, the map's real server, a page over its websocket."""

from __future__ import annotations

import asyncio
import json
import os
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("aiohttp", reason="needs aiohttp (the map extra)")

import aiohttp  # noqa: E402

from alphafence.awareness.sample import Sample  # noqa: E402
from alphafence.awareness.state import Level  # noqa: E402
from alphafence.fencing.pipeline import BuildOptions  # noqa: E402
from alphafence.livemap.observer import LiveMap  # noqa: E402
from alphafence.livemap.server import start_map_server  # noqa: E402
from alphafence.monitor.live import LiveOptions, LiveSource  # noqa: E402
from alphafence.monitor.observe import Step  # noqa: E402
from alphafence.sources.ogc import SourceOptions  # noqa: E402
from tests.live_servers import clear_zones, ed318_zone, insert_zone  # noqa: E402
from tests.test_live_monitor import Companion, square, window  # noqa: E402


async def _page(server, got):
    async with aiohttp.ClientSession() as s:
        async with s.ws_connect(server.url + "ws") as ws:
            async for m in ws:
                got.append(json.loads(m.data))


async def _until(predicate, what, deadline_s=60.0):
    end = time.monotonic() + deadline_s
    while not predicate():
        assert time.monotonic() < end, f"never: {what}"
        await asyncio.sleep(0.02)


def _step(lon, lat):
    return Step(Sample(time.monotonic(), lat, lon, 30.0), time.monotonic(), True, Level.CLEAR, ())


async def test_a_new_zone_appears_on_the_map_with_its_window_and_source(shared_source, rules):
    pg, api, table = shared_source
    clear_zones(pg, table)
    now = datetime.now(timezone.utc)
    in_force = window(now, -timedelta(minutes=1), timedelta(hours=2))
    companion = Companion()
    livemap = LiveMap(companion.engine.fences, near_m=3000.0)
    livemap.on_engine(companion.engine)
    companion.log.add_listener(livemap.on_event)
    options = LiveOptions(SourceOptions(api.collection), rules, BuildOptions())
    live = LiveSource(companion, options, companion.engine.fences.records)
    server = await start_map_server(livemap, "127.0.0.1", 0)
    got = []
    reader = asyncio.ensure_future(_page(server, got))
    try:
        await _until(lambda: livemap.clients, "the page connected")
        livemap.on_step(_step(14.505, 35.905))
        await _until(lambda: any(m["type"] == "fences" for m in got), "the fences near it")
        first = [m for m in got if m["type"] == "fences"][0]
        assert {f["properties"]["site_id"] for f in first["geojson"]["features"]} == {"base/1"}
        insert_zone(pg, table, ed318_zone("FIRE-9", square(14.51, 35.91), "wildfire", in_force))
        async with live.opened():
            await live.refresh()
        livemap.on_step(_step(14.5051, 35.9051))  # the next position: fences gathered again

        def fence_of_zone():
            for m in got:
                if m["type"] == "fences":
                    for f in m["geojson"]["features"]:
                        if f["properties"].get("source_zone") == "FIRE-9":
                            return f
            return None

        await _until(fence_of_zone, "the new zone's fence on the page")
    finally:
        reader.cancel()
        await server.close()
    props = fence_of_zone()["properties"]
    assert props["kind"] in ("keep_out", "warning") and props["zone"]["applicability"] == in_force
    (event,) = [
        m["event"] for m in got if m["type"] == "event" and m["event"]["event"] == "source_zone"
    ]
    assert event["name"] == "wildfire" and event["window"] == "active"
    assert event["applicability"] == in_force and event["source"] == f"{api.collection}/items"


PAGE_STATE = (
    "var l = window.afLive; if (!l) return null;"
    "var live = []; l.layers.fences.eachLayer(function (x) {"
    " var p = x.feature.properties; if (p.source_zone) live.push(p.source_zone); });"
    "return {basemap: l.basemap || 0, fences: l.fences, live: live,"
    " shown: Array.from(document.querySelectorAll('.af-event')).map(e => e.innerText)};"
)


@pytest.mark.browser
async def test_the_page_draws_the_offline_basemap_and_the_new_zone(
    shared_source, rules, malta, local_browser, tmp_path
):
    from alphafence.plots.osm_basemap import osm_basemap

    pg, api, table = shared_source
    clear_zones(pg, table)
    companion = Companion()
    basemap = osm_basemap(malta, (14.48, 35.88, 14.54, 35.93))
    layers = {f["properties"]["layer"] for f in basemap["features"]}
    assert layers == {"road", "water", "place"}
    livemap = LiveMap(companion.engine.fences, near_m=3000.0, basemap=basemap)
    livemap.on_engine(companion.engine)
    companion.log.add_listener(livemap.on_event)
    live = LiveSource(companion, LiveOptions(SourceOptions(api.collection), rules, BuildOptions()),
                      companion.engine.fences.records)  # fmt: skip
    server = await start_map_server(livemap, "127.0.0.1", 0)

    async def state(what, predicate):
        end = time.monotonic() + 120.0
        while True:
            got = await asyncio.to_thread(local_browser.execute_script, PAGE_STATE)
            if got and predicate(got):
                return got
            assert time.monotonic() < end, f"never: {what}: {got}"
            livemap.on_step(_step(14.505, 35.905))
            await asyncio.sleep(0.1)

    try:
        await asyncio.to_thread(local_browser.get, server.url)
        first = await state("the basemap drawn", lambda s: s["basemap"] and s["fences"])
        assert first["basemap"] == len(basemap["features"]) and not first["live"]
        insert_zone(pg, table, ed318_zone("FIRE-9", square(14.51, 35.91), "wildfire"))
        async with live.opened():
            await live.refresh()
        livemap.on_step(_step(14.5051, 35.9051))
        shown = await state("the new zone on the page", lambda s: "FIRE-9" in s["live"])
        assert any("new zone wildfire" in text for text in shown["shown"]), shown["shown"]
        shots = os.environ.get("ALPHAFENCE_SHOTS")  # the docs' picture: run with it set
        picture = ROOT / "docs" / "live-zone.png" if shots else tmp_path / "live-zone.png"
        await asyncio.to_thread(local_browser.save_screenshot, str(picture))
        assert picture.stat().st_size > 10_000
    finally:
        await server.close()
