"""The live map's server: a token off loopback, read-only, only its own pages, and a page that
never reads neither grows its queue beyond the bound nor slows the monitor's checks."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket

import pytest

pytest.importorskip("aiohttp", reason="needs aiohttp (the map extra)")

import aiohttp  # noqa: E402

from alphafence.awareness.fenceset import FenceSet  # noqa: E402
from alphafence.cli.demo import scene_path, trace_path  # noqa: E402
from alphafence.errors import InputError  # noqa: E402
from alphafence.livemap.observer import LiveMap  # noqa: E402
from alphafence.livemap.server import parse_address, start_map_server  # noqa: E402
from alphafence.review.live_replay import replay_live  # noqa: E402
from alphafence.review.replay import Trace, speedup_options  # noqa: E402

DEADLINE_S = 30.0


@pytest.fixture(scope="module")
def demo_fences(tmp_path_factory):
    from alphafence.cli import main

    path = tmp_path_factory.mktemp("livemap") / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(path), "-q"]) == 0
    return FenceSet.from_geojson(path)


async def _until(predicate, what):
    """Wait (polling the loop) until ``predicate()``; fail naming ``what`` after the deadline."""
    loop = asyncio.get_running_loop()
    end = loop.time() + DEADLINE_S
    while not predicate():
        assert loop.time() < end, f"never: {what}"
        await asyncio.sleep(0.02)


def _base(server):
    return f"http://127.0.0.1:{server.port}"


async def test_off_loopback_every_request_needs_the_printed_token(demo_fences):
    server = await start_map_server(LiveMap(demo_fences), "0.0.0.0", 0)
    try:
        assert server.token and f"?token={server.token}" in server.url
        async with aiohttp.ClientSession() as s:
            for path in ("/", "/ws", "/?token=wrong", f"/ws?token={server.token[:-1]}"):
                async with s.get(_base(server) + path) as r:
                    assert r.status == 403, path
            async with s.get(f"{_base(server)}/?token={server.token}") as r:
                assert r.status == 200
                assert "window.afLive" in await r.text()
            async with s.ws_connect(f"{_base(server)}/ws?token={server.token}") as ws:
                hello = json.loads((await ws.receive()).data)
                assert hello["type"] == "hello"
    finally:
        await server.close()


async def test_on_loopback_it_is_read_only_and_only_for_its_own_pages(demo_fences):
    server = await start_map_server(LiveMap(demo_fences), "127.0.0.1", 0)
    try:
        assert server.token is None and server.url == f"{_base(server)}/"
        async with aiohttp.ClientSession() as s:
            async with s.get(server.url) as r:
                assert r.status == 200
            for method in ("POST", "PUT", "DELETE", "PATCH"):
                async with s.request(method, server.url) as r:
                    assert r.status == 405, method
                async with s.request(method, server.url + "ws") as r:
                    assert r.status == 405, method
            # another site's page, and a DNS name rebound to 127.0.0.1
            async with s.get(server.url + "ws", headers={"Origin": "http://evil.example"}) as r:
                assert r.status == 403
            async with s.get(server.url, headers={"Host": f"evil.example:{server.port}"}) as r:
                assert r.status == 403
            # what a page sends is never read: the server goes on sending
            async with s.ws_connect(server.url + "ws", origin=_base(server)) as ws:
                await ws.send_str(json.dumps({"command": "arm"}))
                assert json.loads((await ws.receive()).data)["type"] == "hello"
    finally:
        await server.close()


def test_a_bad_address_is_one_line():
    with pytest.raises(InputError, match="--map-server 127.0.0.1:http: give HOST:PORT"):
        parse_address("127.0.0.1:http")


def _stuck_page(port):
    """A WebSocket page that opens and then never reads (its receive buffer kept tiny)."""
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    return sock


async def _replay(fences, livemap=None):
    trace = Trace.read(trace_path())
    options = speedup_options(trace.speedup, enforce=True)
    return await replay_live(trace, fences, options, [livemap] if livemap else [])


async def test_a_page_that_never_reads_is_bounded_then_dropped_and_slows_no_check(demo_fences):
    alone = await _replay(demo_fences)
    # the page is dropped once one message has waited longer than the replay lasts
    livemap = LiveMap(demo_fences, queue_max=2, send_timeout_s=15.0)
    for k in range(200):  # a long history, more than the page's buffers hold
        livemap.on_event({"time": 0.0, "event": "earlier", "text": f"{k} " + "x" * 1000})
    server = await start_map_server(livemap, "127.0.0.1", 0)
    sock = _stuck_page(server.port)
    try:
        await _until(lambda: livemap.clients, "the page connected")
        (client,) = livemap.clients
        watched = await _replay(demo_fences, livemap)
        await _until(lambda: livemap.dropped_clients == 1, "the stuck page dropped")
        assert not livemap.clients
        # the queue never held more than its bound: the events beyond it were dropped
        assert client.peak <= 2
        assert client.dropped > 0
        assert len(watched.events) > 2
        # every position was still checked as it came (none waited behind the page)
        assert watched.steps >= 0.9 * alone.steps
        assert livemap.steps == watched.steps
    finally:
        sock.close()
        await server.close()


async def _page(server, got):
    """A page: every message the map sends, decoded, into ``got``."""
    async with aiohttp.ClientSession() as s:
        async with s.ws_connect(server.url + "ws") as ws:
            async for m in ws:
                got.append(json.loads(m.data))


async def test_a_page_gets_the_vehicle_fences_near_it_its_own_fence_and_the_events(demo_fences):
    livemap = LiveMap(demo_fences, near_m=400.0)
    server = await start_map_server(livemap, "127.0.0.1", 0)
    got = []
    reader = asyncio.ensure_future(_page(server, got))
    try:
        await _until(lambda: livemap.clients, "the page connected")
        done = await _replay(demo_fences, livemap)
        kinds = [e["event"] for e in done.events]
        await _until(lambda: sum(m["type"] == "event" for m in got) == len(kinds), "every event")
    finally:
        reader.cancel()
        await server.close()
    assert [m["event"]["event"] for m in got if m["type"] == "event"] == kinds
    vehicle = [m for m in got if m["type"] == "vehicle"]
    assert len({(v["lat"], v["lon"]) for v in vehicle}) > 10
    assert "IMMINENT" in {v["level"] for v in vehicle}
    moving = [v for v in vehicle if v["heading_deg"] is not None]
    assert moving and all(len(v["path"]) == 2 for v in moving)
    fences = [m for m in got if m["type"] == "fences"]
    # the fences near the vehicle, not all of them, the site it flew at among them; sent
    # again once it had moved a quarter of the distance from where they were gathered
    sent = fences[0]["geojson"]["features"]
    assert 0 < len(sent) == fences[0]["sent"] < len(demo_fences.records)
    assert "hospital/way/1007" in {f["properties"]["site_id"] for f in sent}
    assert len(fences) >= 2 and fences[0]["center"] != fences[-1]["center"]
    onboard = [m for m in got if m["type"] == "onboard"][-1]
    assert onboard["items"] == len(Trace.read(trace_path()).onboard_items)
    assert len(onboard["geojson"]["features"]) == sum(
        n for n in [e for e in done.events if e["event"] == "onboard_fence"][0]["fences"].values()
    )


async def test_a_page_gets_other_aircraft_in_their_cylinders_and_each_new_onboard_fence(
    demo_fences,
):
    from alphafence.awareness.predict import dynamic_radius
    from alphafence.monitor.engine import Engine
    from alphafence.monitor.observe import Step

    trace = Trace.read(trace_path())
    engine = Engine(demo_fences, speedup_options(trace.speedup))
    livemap = LiveMap(demo_fences)
    livemap.on_engine(engine)
    got = []

    async def send(text):
        got.append(json.loads(text))

    page = livemap.connect()
    serving = asyncio.ensure_future(livemap.serve(page, send))
    try:
        # an aircraft 300 m north of the vehicle flying south at 20 m/s, head on
        s = trace.samples[-1]
        x, y = demo_fences.frame.to_local(s.lon, s.lat)
        lon, lat = (float(v) for v in demo_fences.frame.to_wgs84(float(x), float(y) + 300.0))
        report = dict(key="4ca123", lat=lat, lon=lon, alt_amsl_m=s.alt_amsl_m, ve=0.0, vn=-20.0,
                      callsign="TEST1")  # fmt: skip
        engine.aircraft(t=s.t, **report)
        livemap.on_value("adsb", s.t, report)
        events = engine.step(s)
        livemap.on_step(Step(s, s.t, True, engine.sm.level, tuple(events)))
        for e in events:
            livemap.on_event(e)
        assert "traffic_conflict" in [e["event"] for e in events]
        await _until(lambda: any(m["type"] == "traffic" and m["aircraft"] for m in got), "traffic")
        (a,) = [m for m in got if m["type"] == "traffic" and m["aircraft"]][-1]["aircraft"]
        closing = 20.0 + s.vn  # it flies south at 20 m/s, the vehicle north at s.vn
        assert a["callsign"] == "TEST1" and a["conflict"] is True
        assert a["radius_m"] == pytest.approx(
            dynamic_radius(150.0, closing, 2.0), abs=abs(s.ve) * 2.0 + 0.1
        )
        # a new fence on the vehicle (a rolling upload's): the page gets it as it is loaded
        items = trace.onboard_items[:12]  # its first polygon alone
        for e in engine.load_onboard(items, t=s.t, cause="upload"):
            livemap.on_event(e)
        await _until(
            lambda: any(m["type"] == "onboard" and m["cause"] == "upload" for m in got), "upload"
        )
        onboard = [m for m in got if m["type"] == "onboard"][-1]
        assert onboard["items"] == 12 and len(onboard["geojson"]["features"]) == 1
    finally:
        serving.cancel()


@pytest.mark.parametrize(
    "argv",
    [
        ["monitor", "--connect", "udpin://127.0.0.1:14550", "--allow-unsigned"],
        ["demo", "--replay"],
    ],
)
def test_a_bad_map_address_is_one_line_before_anything_runs(argv, tmp_path, capsys):
    from alphafence.cli import main

    fences = tmp_path / "fences.geojson"
    fences.write_text('{"type": "FeatureCollection", "features": []}')
    extra = ["--fences", str(fences)] if argv[0] == "monitor" else ["-o", str(tmp_path / "o")]
    assert main([*argv, *extra, "--map-server", "127.0.0.1:http"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"alphafence {argv[0]}: error: --map-server 127.0.0.1:http: give HOST:PORT "
                   "(a port 0-65535; 0 picks a free one)"]  # fmt: skip
    assert not (tmp_path / "o").exists()


async def test_the_monitors_live_map_follows_its_checks_and_events():
    from types import SimpleNamespace

    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from tests.test_monitor_observer import NORTH, Action, Recorder, Telemetry, fences

    recorder = Recorder()
    telemetry = Telemetry(recorder)
    vehicle = SimpleNamespace(telemetry=telemetry, action=Action(), system=None)
    watched = fences()
    livemap = LiveMap(watched)
    log = EventLog(None)
    monitor = Monitor(vehicle, watched, MonitorOptions(), log, observers=[recorder, livemap])
    monitor.feeds.pop("adsb")  # no MAVSDK system behind the stub: no ADS-B

    async def alert(text, event):
        pass

    monitor.commands.alert = alert
    assert livemap.engine is monitor.engine  # told of the engine when added
    server = await start_map_server(livemap, "127.0.0.1", 0)
    got = []
    reader = asyncio.ensure_future(_page(server, got))
    stop = asyncio.Event()
    try:
        await _until(lambda: livemap.clients, "the page connected")
        task = asyncio.create_task(monitor.run(stop))
        await asyncio.wait_for(telemetry.done.wait(), DEADLINE_S)
        await _until(
            lambda: sum(m["type"] == "event" for m in got) == len(log.events), "every event"
        )
        await _until(
            lambda: any(m["type"] == "vehicle" and m["checks"] == len(NORTH) for m in got),
            "the last position",
        )
        stop.set()
        await asyncio.wait_for(task, 5)
    finally:
        reader.cancel()
        await server.close()
    assert livemap.steps == monitor.engine.checks == len(NORTH)
    assert [m["event"] for m in got if m["type"] == "event"] == list(log.events)
    levels = [m["level"] for m in got if m["type"] == "vehicle"]
    assert levels[0] == "CLEAR" and levels[-1] == "BREACH"
