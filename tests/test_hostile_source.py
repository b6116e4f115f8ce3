"""A live source that no server can turn against the vehicle: each misbehaviour of
``tests/hostile_server.py`` (a real server on loopback) asked by the client, by ``build
--source`` and by the monitor's polling loop. The promises: one line, exit 4 or 2, nothing
written, nothing in force lost, the token never sent to another origin, and the polling alive
afterwards (a new zone served next is taken)."""

from __future__ import annotations

import asyncio
import json
from urllib.parse import urljoin

import pytest

from alphafence.cli import main
from alphafence.errors import SourceError
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencing.pipeline import BuildOptions
from alphafence.monitor.live import LiveOptions, LiveSource
from alphafence.sources.answers import read_zones
from alphafence.sources.ogc import SourceOptions, fetch, session
from tests.hostile_server import CASES, HostileServer
from tests.live_servers import ed318_zone
from tests.test_live_monitor import Companion, square

TOKEN = "s3cret-token"
BOX = "14.4,35.8,14.6,36.0"

# what the client makes of each case: (outcome, what its line says)
CLIENT = {
    None: ("complete", ""),
    "next-self": ("incomplete", "page 2's next link leads back to page 2: the pages loop"),
    "next-back": ("incomplete", "page 3's next link leads back to page 2: the pages loop"),
    "returned-more": ("incomplete", "page 1 says numberReturned"),
    "matched-fewer": ("incomplete", "3 features read of the 2 it matched"),
    "nan-vertex": ("complete", ""),
    "all-malformed": ("complete", ""),
    "date-9999": ("complete", ""),
    "clock-far-off": ("complete", ""),
    "deep-body": ("raises", "answer nested 200000 deep (at most 64 is read): not read"),
    "deep-coordinates": ("raises", "answer nested 505 deep"),
    "nested-coordinates": ("complete", ""),
    "not-modified-unasked": ("raises", "HTTP 304 Not Modified to a request that was not"),
    "hostile-windows": ("complete", ""),
    "next-other-origin": ("incomplete", "page 1's next link to another origin"),
    "next-file": ("incomplete", "page 1's next link to a file: URL, not followed"),
    "redirect-other-port": ("raises", "HTTP 302 redirect to another origin"),
    "redirect-file": ("raises", "HTTP 302 redirect to a file: URL, not followed"),
    "redirect-data": ("raises", "HTTP 302 redirect to a data: URL, not followed"),
    "redirect-loop": ("raises", "more than 5 redirects: not followed"),
    "huge-pages": ("incomplete", "answer larger than 8 MiB over 3 pages: the rest was not read"),
    "many-features": ("incomplete", "more than 12 features: the rest was not read"),
    "reset": ("raises", "answer cut short"),
    "early-close": ("raises", "answer cut short"),
    "silent": ("raises", "no answer within 2 s"),
    "trickle": ("raises", "no answer within 2 s"),
    "gzip-bomb": ("raises", "MiB: not read"),
    "html": ("raises", "answer is not GeoJSON (content type text/html)"),
    "wrong-type": ("raises", "answer is not GeoJSON (content type application/xml)"),
    "not-collection": ("raises", "answer is not a GeoJSON FeatureCollection (a Feature)"),
    "partial": ("incomplete", "HTTP 503: server error"),
    "empty": ("complete", ""),
}
SLOW = {"silent", "trickle"}  # cut by the client's timeout, not answered


def zones(*names):
    return [ed318_zone(n, square(14.51 + 0.01 * k, 35.91)) for k, n in enumerate(names)]


@pytest.fixture(scope="module")
def servers():
    """The hostile server serving zones A, B and C, and another origin beside it."""
    with HostileServer(zones("A", "B", "C")) as other:
        with HostileServer(zones("A", "B", "C"), other=other.url) as hostile:
            hostile.pad, hostile.extra = 3 * 2**20, 5
            yield hostile, other


def options(url, case, **kw) -> SourceOptions:
    kw = {"token": TOKEN, "limit": 2, "retries": 0, "max_bytes": 4 * 2**20,
          "max_answer_bytes": 8 * 2**20, "max_features": 12,
          "timeout_s": 2.0 if case in SLOW else 60.0, **kw}  # fmt: skip
    return SourceOptions(url, **kw)


async def ask(o):
    async with session(o) as http:
        return await fetch(http, o, (14.4, 35.8, 14.6, 36.0))


def test_the_catalogue_is_asked_whole():
    assert set(CLIENT) - {None} == set(CASES)


async def asked(hostile, other, case, o):
    """Ask the source serving ``case``; AssertionError when the client breaks a promise."""
    hostile.case, hostile.requests[:], other.requests[:] = case, [], []
    outcome, said = CLIENT[case]
    if outcome == "raises":
        with pytest.raises(SourceError) as err:
            await ask(o)
        line = str(err.value)
    else:
        answer = await ask(o)
        assert answer.complete == (outcome == "complete"), answer.error
        line = str(answer.error or "")
    assert said in line and "\n" not in line, line
    assert TOKEN not in line
    assert not other.requests, "another origin was asked"
    assert len(hostile.authorized()) == len(hostile.requests), "the source's own token missing"


@pytest.mark.parametrize("case", list(CLIENT), ids=str)
async def test_each_case_is_one_line_and_never_a_complete_answer_it_is_not(servers, case):
    hostile, other = servers
    await asked(hostile, other, case, options(hostile.collection, case))


async def test_a_named_origin_is_followed_with_the_token(servers):
    hostile, other = servers
    hostile.case, other.case, other.requests[:] = "next-other-origin", None, []
    answer = await ask(options(hostile.collection, None, also_origins=(other.url,)))
    assert other.authorized(), "the named origin did not get the token"
    assert answer.complete and sorted(f["id"] for f in answer.features) == ["A", "B", "C"]
    hostile.case = None


@pytest.mark.parametrize("case", ["next-other-origin", "redirect-other-port", "next-self"])
async def test_broken_a_client_that_follows_any_link_is_caught(servers, monkeypatch, case):
    """Broken on purpose: ``next`` links and redirects followed wherever they lead, the token
    as a session header (as it was), a page seen before not noticed. The promises fail."""
    import alphafence.sources.ogc as ogc
    import alphafence.sources.request as request

    hostile, other = servers
    loose = lambda options, base, href, what: urljoin(base, href)  # noqa: E731
    monkeypatch.setattr(ogc, "follow", loose)
    monkeypatch.setattr(request, "follow", loose)
    monkeypatch.setattr(request, "origin", lambda url: "any")
    monkeypatch.setattr(ogc.SourceOptions, "origins", property(lambda self: ("any",)))
    if case == "next-self":
        monkeypatch.setattr(ogc.SourceOptions, "max_pages", 3)
        monkeypatch.setattr(ogc, "_check_matched", lambda answer: None)

        class Forgets(dict):
            def __setitem__(self, key, value):
                pass

        real = ogc._read_page

        async def forgetful(http, options, answer, page_url, conditional, seen, keep):
            return await real(http, options, answer, page_url, conditional, Forgets(), keep)

        monkeypatch.setattr(ogc, "_read_page", forgetful)
    with pytest.raises((AssertionError, pytest.fail.Exception)):
        await asked(hostile, other, case, options(hostile.collection, case))
    hostile.case = None


# build --source: exit status and what its one line says; nothing written but for 0
BUILD = {case: (4, said) for case, (outcome, said) in CLIENT.items() if outcome != "complete"}
BUILD.update({
    None: (0, ""), "date-9999": (0, ""), "clock-far-off": (0, ""), "empty": (0, ""),
    "hostile-windows": (0, ""),
    "nan-vertex": (2, "zone A: Polygon coordinate is not a finite number (nan)"),
    "nested-coordinates": (2, "zone A: Polygon coordinates nested deeper than a Polygon"),
    "all-malformed": (4, "none of its 3 features is a zone, nothing written"),
})  # fmt: skip


@pytest.mark.parametrize("case", list(BUILD), ids=str)
def test_build_says_one_line_and_writes_nothing_but_a_complete_answer(
    servers, case, tmp_path, capsys, monkeypatch
):
    hostile, other = servers
    hostile.case, other.requests[:] = case, []
    monkeypatch.setenv("ALPHAFENCE_SOURCE_TOKEN", TOKEN)
    out = tmp_path / "copy.geojson"
    status = main(["build", "--source", hostile.collection, "--bbox", BOX, "-o", str(out),
                   "--source-max-bytes", "8", "--source-max-features", "12",
                   "--source-timeout", "2" if case in SLOW else "60"])  # fmt: skip
    captured = capsys.readouterr()
    err, out_lines = captured.err.strip(), captured.out.strip().splitlines()
    code, said = BUILD[case]
    assert status == code, err
    if code:
        assert said in err and len(err.splitlines()) == 1, err
        assert not out.exists() and not list(tmp_path.iterdir())
    else:
        doc = json.loads(out.read_text())
        assert doc["alphafence"]["source"]["complete"] is True
        served = {f["properties"]["source_zone"] for f in doc["features"]}
        assert served == (set() if case == "empty" else {"A", "B", "C"})
        # the summary, longer than 120 columns, is one line in a pipe
        (summary,) = [line for line in out_lines if "fences; wrote" in line]
        assert len(summary) > 120 and summary.endswith(f"wrote {out}"), out_lines
    assert not other.requests and TOKEN not in err


def test_an_empty_source_gives_an_empty_offline_copy(servers, tmp_path, capsys):
    hostile, _ = servers
    hostile.case = "empty"
    out = tmp_path / "copy.geojson"
    assert main(["build", "--source", hostile.collection, "--bbox", BOX, "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "serves no zone in the area" in err
    doc = json.loads(out.read_text())
    assert doc["features"] == [] and doc["alphafence"]["source"]["url"].endswith("/items")
    assert read_fences(out) == []


def test_a_skipped_malformed_zone_is_left_out_with_one_note(servers, tmp_path, capsys):
    hostile, _ = servers
    hostile.case = "nan-vertex"
    out = tmp_path / "copy.geojson"
    args = ["build", "--source", hostile.collection, "--bbox", BOX, "-o", str(out)]
    assert main([*args, "--skip-invalid"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "left out (--skip-invalid)" in err[0], err
    served = {f.properties["source_zone"] for f in read_fences(out)}
    assert served == {"B", "C"}


# the monitor: the kind of event each case gives, and what its line says
MONITOR = {
    case: ("source_failed" if outcome == "raises" else "source_incomplete", said)
    for case, (outcome, said) in CLIENT.items()
    if outcome != "complete"
}
MONITOR.update({
    "nan-vertex": ("source_zone_kept", "served malformed: kept as it was"),
    "nested-coordinates": ("source_zone_kept", "served malformed: kept as it was"),
    "all-malformed": ("source_failed", "features is a zone: taken as a failed answer"),
    "next-self": ("source_incomplete", "the pages loop"),
    "next-back": ("source_incomplete", "the pages loop"),
    "matched-fewer": ("source_incomplete", "features read of the"),
    "date-9999": ("source_clock", "its Date is not applied"),
    "clock-far-off": ("source_clock", "its Date is not applied"),
    "empty": ("source_empty", "kept until a second one"),
    "hostile-windows": ("source_zone", ""),  # new versions, each in force: unreadable windows
})  # fmt: skip


async def take(live, case, server):
    """Serve ``case``, ask the source now (a ground station's hint), wait for its end."""
    server.case = case
    asked = asyncio.ensure_future(live.next_refresh())
    live.hint()
    await asked


async def test_the_polling_outlives_every_case_and_keeps_every_zone_in_force(servers):
    hostile, other = servers
    hostile.case = None
    companion = Companion()
    o = LiveOptions(options(hostile.collection, None, timeout_s=60.0), None, BuildOptions(),
                    refresh_s=3600.0, stale_after_s=3600.0)  # fmt: skip
    from alphafence.zones.rules import load_rules

    o.rules = load_rules()
    live = LiveSource(companion, o, companion.engine.fences.records)
    stop = asyncio.Event()
    first = asyncio.ensure_future(live.next_refresh())
    task = asyncio.create_task(live.run(stop))
    await first
    assert companion.in_force() == {"A", "B", "C"}, companion.log.events
    try:
        for k, case in enumerate(MONITOR):
            live.options.source = options(hostile.collection, case)
            seen = len(companion.log.events)
            await take(live, case, hostile)
            events = list(companion.log.events)[seen:]
            kind, said = MONITOR[case]
            lines = [e.get("error") or e.get("reason") or "" for e in events if e["event"] == kind]
            assert any(said in line for line in lines), (case, events)
            assert all("\n" not in line and TOKEN not in line for line in lines)
            assert {"A", "B", "C"} <= companion.in_force(), (case, "a zone in force was lost")
            assert not task.done(), (case, "the polling ended")
            live.tick(datetime_now())  # each second's window work, as the monitor does it
            # polling alive: a new zone served next is taken at the next answer
            hostile.zones.append(ed318_zone(f"N{k}", square(14.40 + 0.003 * k, 35.85)))
            live.options.source = options(hostile.collection, None, max_features=10_000)
            await take(live, None, hostile)
            assert f"N{k}" in companion.in_force(), (case, list(companion.log.events)[seen:])
            assert companion.clock_slack_s <= 30.0, "a hostile Date widened the windows"
        assert not other.requests
    finally:
        stop.set()
        live.hint()
        await task
        del hostile.zones[3:]


def datetime_now():
    from datetime import datetime, timezone

    return datetime.now(timezone.utc)


def test_read_zones_names_a_malformed_zone_and_holds_its_id():
    from alphafence.zones.rules import load_rules
    from tests.hostile_server import deep_zone, nan_zone

    good = zones("A", "B", "C")
    features = [nan_zone(good[0]), deep_zone(good[1], 40), good[2]]
    held = []
    found, bad = read_zones("src", features, load_rules(), held=held)
    assert [z.id for z in found] == ["C"] and held == ["A", "B"]
    assert "zone A: Polygon coordinate is not a finite number (nan)" in bad[0]
    assert "zone B: Polygon coordinates nested deeper" in bad[1]


def test_build_follows_an_origin_the_user_names_and_no_other(
    servers, tmp_path, capsys, monkeypatch
):
    hostile, other = servers
    hostile.case, other.case, other.requests[:] = "next-other-origin", None, []
    monkeypatch.setenv("ALPHAFENCE_SOURCE_TOKEN", TOKEN)
    out = tmp_path / "copy.geojson"
    args = ["build", "--source", hostile.collection, "--bbox", BOX, "-o", str(out), "-q"]
    assert main(args) == 4 and not out.exists() and not other.requests
    assert "allow it with --source-origin" in capsys.readouterr().err
    assert main([*args, "--source-origin", other.url]) == 0
    assert other.authorized() and out.exists()
    assert main([*args, "--source-origin", "file:///etc"]) == 2
    assert "not an http:// or https:// origin" in capsys.readouterr().err
    hostile.case = None
