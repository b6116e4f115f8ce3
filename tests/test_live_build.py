"""``build --source``: the offline copy of a live source (pygeoapi over PostGIS on loopback),
the monitor starting from it, and a build written to PostGIS tables that the same kind of
server serves back to a companion as fences."""

from __future__ import annotations

import asyncio
import json

import pytest

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencing.pipeline import BuildOptions
from alphafence.monitor.live import LiveOptions, LiveSource
from alphafence.monitor.live_zones import split_copy
from alphafence.sources.ogc import SourceOptions
from tests.live_servers import (
    NO_POSTGIS,
    PostGIS,
    Pygeoapi,
    clear_zones,
    delete_zone,
    ed318_zone,
    insert_zone,
    postgres_provider,
)
from tests.test_live_monitor import Companion, square

BOX = "14.4,35.8,14.6,36.0"


@pytest.fixture
def zones(shared_source):
    pg, api, table = shared_source
    clear_zones(pg, table)
    insert_zone(pg, table, ed318_zone("A", square(14.51, 35.91), name="fire"))
    insert_zone(pg, table, ed318_zone("B", square(14.52, 35.91)))
    insert_zone(pg, table, ed318_zone("FAR", square(15.5, 36.5)))
    return shared_source


def test_the_offline_copy_records_the_source_and_fences_each_zone(zones, tmp_path):
    _, api, _ = zones
    out = tmp_path / "copy.geojson"
    assert main(["build", "--source", api.collection, "--bbox", BOX, "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    source = doc["alphafence"]["source"]
    assert source["url"] == f"{api.collection}/items" and source["complete"] is True
    assert source["fetched_utc"].endswith("Z") and source["bbox"] == [14.4, 35.8, 14.6, 36.0]
    fences = read_fences(out)
    assert {(f.properties["source_zone"], f.kind) for f in fences} == {
        ("A", "keep_out"), ("A", "warning"), ("B", "keep_out"), ("B", "warning")}  # fmt: skip
    base, copied = split_copy(fences)
    assert not base and len(copied) == 4


def test_a_source_with_a_malformed_zone_writes_nothing_unless_skipped(zones, tmp_path, capsys):
    pg, api, table = zones
    bad = ed318_zone("BAD", square(14.53, 35.91))
    bad["properties"]["type"] = ""
    insert_zone(pg, table, bad)
    out = tmp_path / "copy.geojson"
    assert main(["build", "--source", api.collection, "--bbox", BOX, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "zone BAD: missing zone type" in err and not out.exists()
    args = ["build", "--source", api.collection, "--bbox", BOX, "-o", str(out), "--skip-invalid"]
    assert main(args) == 0
    assert "left out (--skip-invalid)" in capsys.readouterr().err
    assert {f.properties["source_zone"] for f in read_fences(out)} == {"A", "B"}


def test_an_unreachable_source_is_one_line_and_nothing_written(tmp_path, capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "copy.geojson"
    url = f"http://127.0.0.1:{port}/collections/zones"
    assert main(["build", "--source", url, "--bbox", BOX, "-o", str(out)]) == 4
    err = capsys.readouterr().err.strip()
    assert "connection refused" in err and "\n" not in err and not out.exists()


async def test_the_monitor_starts_from_the_copy_when_the_source_is_down(zones, tmp_path, rules):
    import socket

    pg, api, table = zones
    out = tmp_path / "copy.geojson"
    args = ["build", "--source", api.collection, "--bbox", BOX, "-o", str(out), "-q"]
    assert await asyncio.to_thread(main, args) == 0  # the command runs its own event loop
    base, copied = split_copy(read_fences(out))
    companion = Companion(copied)  # the monitor's --fences: the copy
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        down = f"http://127.0.0.1:{s.getsockname()[1]}/collections/zones"
    options = LiveOptions(SourceOptions(down, retries=0), rules, BuildOptions(), refresh_s=1.0)
    live = LiveSource(companion, options, *split_copy(companion.engine.fences.records))
    assert companion.in_force() == {"A", "B"}
    async with live.opened():
        await live.refresh()
        assert companion.in_force() == {"A", "B"}
        assert "connection refused" in companion.events("source_failed")[-1]["error"]
        live.options.source = SourceOptions(api.collection)  # the source is back
        await live.refresh()
        assert not companion.events("source_fences")  # the copy's zones: nothing rebuilt
        assert not companion.events("source_zone")
        delete_zone(pg, table, "B")
        await live.refresh()
        assert companion.in_force() == {"A"}
        assert [e["zone"] for e in companion.events("source_zone_removed")] == ["B"]


async def test_a_build_written_to_postgis_is_served_back_as_fences(
    shared_source, tmp_path, rules, capsys
):
    pg, _, _ = shared_source
    if not isinstance(pg, PostGIS):
        pytest.skip(f"{NO_POSTGIS}: the zones are a file here, no database to write to")
    from importlib import resources

    scene = str(resources.files("alphafence").joinpath("data/demo-scene.geojson"))
    fences_url = pg.url + "/public.fleet_fences"
    zones_url = pg.url + "/fleet.zones"
    args = ["build", scene, "-o", fences_url, "--zones-table", zones_url, "-q"]
    assert main(args) == 0
    assert main(args) == 0  # written again: the next version, the same rows
    assert capsys.readouterr().out == ""  # -q: nothing
    assert main(args[:-1]) == 0  # a third time, saying what it wrote (no temporary file)
    wrote = [line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote")]
    count = pg.sql("SELECT count(*) FROM public.fleet_fences")[0][0]
    assert wrote == [f"wrote {count} fences to {fences_url} (version 3)",
                     f"wrote 16 zones to {zones_url}"], wrote  # fmt: skip
    rows = pg.sql("SELECT count(*), min(version), max(version) FROM public.fleet_fences")
    local = tmp_path / "fences.geojson"
    assert main(["build", scene, "-o", str(local), "-q"]) == 0
    expected = read_fences(local)
    assert rows == [(len(expected), 3, 3)]
    assert pg.sql("SELECT count(*) FROM fleet.zones")[0][0] == 16  # the scene's features
    index = pg.sql("SELECT indexdef FROM pg_indexes WHERE tablename = 'fleet_fences'")
    assert any("gist" in row[0] for row in index)
    api = Pygeoapi(tmp_path / "api", postgres_provider(pg, "fleet_fences")).start()
    try:
        import shapely

        from alphafence.fencefiles.fence_geojson import FenceRecord

        anchor = FenceRecord("anchor", "keep_out", shapely.box(-0.58, 51.42, -0.579, 51.421))
        companion = Companion([anchor])  # fences at Egham too: the area asked covers the scene
        options = LiveOptions(SourceOptions(api.collection), rules, BuildOptions())
        live = LiveSource(companion, options, companion.engine.fences.records)
        async with live.opened():
            await live.refresh()
        served = [r for r in companion.engine.fences.records if "source_zone" in r.properties]
        assert len(served) == len(expected)
        key = lambda r: (r.site_id, r.kind)  # noqa: E731
        for got, want in zip(sorted(served, key=key), sorted(expected, key=key)):
            assert key(got) == key(want) and got.geometry.equals_exact(want.geometry, 1e-9)
    finally:
        api.stop()
    bad = pg.url + "/public.fences; DROP TABLE x"
    assert main(["build", scene, "-o", bad, "-q"]) == 2
    assert "is not a plain SQL name" in capsys.readouterr().err


def test_compile_takes_the_sources_zones_in_the_operating_area(zones, tmp_path):
    import shapely

    from alphafence.fencefiles.qgc_plan import read_plan_geofence
    from alphafence.onboard.decode import breached, decode_fence

    _, api, _ = zones
    local = tmp_path / "local.geojson"
    assert main(["build", "--source", api.collection, "--bbox", BOX, "-o", str(local), "-q"]) == 0
    doc = json.loads(local.read_text())  # the local file: zone A's fences only
    doc["features"] = [f for f in doc["features"] if f["properties"]["source_zone"] == "A"]
    local.write_text(json.dumps(doc))
    box = "14.505,35.905,14.53,35.92"
    alone, both = tmp_path / "alone.plan", tmp_path / "both.plan"
    assert main(["compile", str(local), "--bbox", box, "-o", str(alone)]) == 0
    assert main(["compile", str(local), "--bbox", box, "-o", str(both), "--source",
                 api.collection]) == 0  # fmt: skip

    def held(path):  # zone B's corners and centre, each inside an exclusion of the plan
        fences = decode_fence(read_plan_geofence(path).items)
        points = [
            *square(14.52, 35.91)[:4],
            tuple(shapely.Polygon(square(14.52, 35.91)).centroid.coords[0]),
        ]
        return [breached(fences, lon, lat) for lon, lat in points]

    assert not any(held(alone)) and all(held(both))


@pytest.fixture
def web_folder(tmp_path):
    """A plain web server (Python's) on loopback serving a folder: ``(folder, base URL)``."""
    import functools
    import http.server
    import threading

    folder = tmp_path / "www"
    folder.mkdir()
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(folder))
    handler.log_message = lambda *a: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield folder, f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


async def test_a_signed_fence_bundle_on_a_web_server_is_verified_at_every_answer(
    web_folder, tmp_path, rules
):
    import os
    import shutil
    from importlib import resources

    folder, base = web_folder
    scene = str(resources.files("alphafence").joinpath("data/demo-scene.geojson"))
    fences = folder / "fences.geojson"
    key, pub = tmp_path / "ops.pem", tmp_path / "ops.pub.pem"
    for args in (["build", scene, "-o", str(fences), "-q"],
                 ["bundle", "keygen", "--private", str(key), "--public", str(pub)],
                 ["bundle", "sign", str(fences), "--key", str(key)]):  # fmt: skip
        assert await asyncio.to_thread(main, args) == 0
    import shapely

    from alphafence.fencefiles.fence_geojson import FenceRecord

    anchor = FenceRecord("anchor", "keep_out", shapely.box(-0.58, 51.42, -0.579, 51.421))
    companion = Companion([anchor])
    options = LiveOptions(SourceOptions(f"{base}/fences.geojson"), rules, BuildOptions(),
                          trusted_keys=(str(pub),))  # fmt: skip
    live = LiveSource(companion, options, companion.engine.fences.records)
    expected = {r.site_id for r in read_fences(fences)}
    async with live.opened():
        await live.refresh()
        served = {
            r.site_id for r in companion.engine.fences.records if "source_zone" in r.properties
        }
        assert served == expected and not companion.events("source_failed")
        await live.refresh()  # unchanged (If-Modified-Since): nothing rebuilt
        assert companion.events("source_answer")[-1].get("not_modified") is True
        swaps = len(companion.events("source_fences"))
        doc = json.loads(fences.read_text())  # tampered on the server: one fence dropped
        doc["features"] = doc["features"][1:]
        fences.write_text(json.dumps(doc))
        os.utime(fences, (fences.stat().st_mtime + 5,) * 2)
        await live.refresh()
        failed = companion.events("source_failed")[-1]["error"]
        assert "not authentic, not applied: the fences changed after they were signed" in failed
        assert len(companion.events("source_fences")) == swaps  # nothing in force changed
        shutil.copy(fences, tmp_path / "resigned.geojson")
        assert (
            await asyncio.to_thread(main, ["bundle", "sign", str(fences), "--key", str(key)]) == 0
        )
        await live.refresh()  # signed again: applied, the dropped fence lifted
        served = {
            r.site_id for r in companion.engine.fences.records if "source_zone" in r.properties
        }
        assert len(served) <= len(expected) and companion.events("source_zone_removed")
