"""alphafence demo: the main job on the shipped synthetic demo scene.

Build the fences (and compare the methods), compile them into a copter's 560 bytes, and, when
an ArduPilot SITL binary is found, upload them to SITL and fly at a fence with the enforcing
monitor running; without SITL, replay a flight recorded from SITL through the monitor.
"""

from __future__ import annotations

import asyncio
import signal
from importlib import resources
from pathlib import Path

from alphafence.cli.common import out_console
from alphafence.cli.tables import stats_table
from alphafence.errors import InputError, need
from alphafence.fencing import METHODS

NOTE = "Synthetic demo scene authored by the AlphaFence project (not real places)."
HOME = (-0.5500, 51.4300)  # lon, lat: the scene's take-off point (the egham SITL home)
SPEEDUP = 5.0


def scene_path() -> Path:
    """The shipped synthetic demo scene (GeoJSON)."""
    return Path(str(resources.files("alphafence").joinpath("data/demo-scene.geojson")))


def trace_path() -> Path:
    """The shipped trace of the demo's flight, recorded from ArduPilot SITL."""
    return Path(str(resources.files("alphafence").joinpath("data/demo-flight.trace.jsonl")))


def register(sub):
    """Add the ``demo`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "demo",
        help="build fences for the shipped synthetic demo scene and fly at one (SITL or replay)",
        description="Run the main job on the synthetic demo scene: build and compare fences, "
        "compile them for a copter and, with ArduPilot SITL, upload them and fly at a fence "
        "with the enforcing monitor (without SITL: replay a flight recorded from SITL).",
    )
    p.add_argument(
        "-o",
        "--output-dir",
        default="demo-out",
        metavar="DIR",
        help="where to write (default demo-out)",
    )
    p.add_argument(
        "--replay",
        action="store_true",
        help="replay the recorded SITL flight even when a SITL binary is found",
    )
    p.add_argument(
        "--map-server",
        metavar="HOST:PORT",
        help="with --replay: serve a live map of the replayed flight at http://HOST:PORT/ "
        "(as 'alphafence monitor --map-server'); the replay starts, as recorded, when a page "
        "opens the map, and the map stays up until Ctrl-C",
    )
    p.add_argument(
        "--speedup",
        type=float,
        default=SPEEDUP,
        metavar="N",
        help=f"SITL speedup for the flight (default {SPEEDUP:g})",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    """Build, draw and compare fences for the demo scene, compile them, and fly (or replay)
    the demo flight, all into ``--output-dir``; exit 0."""
    from alphafence.fencefiles import qgc_plan
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencefiles.fence_geojson import read_fences
    from alphafence.mavlink.storage import PROFILES
    from alphafence.onboard.compile import compile_fences

    need(("scipy", "building the demo's fences"), ("matplotlib", "drawing the demo's figures"))
    if args.map_server:
        from alphafence.livemap.server import parse_address

        if not args.replay:
            raise InputError("--map-server", "shows the replayed flight: add --replay")
        need(("aiohttp", "--map-server"))
        parse_address(args.map_server)
    out = Path(args.output_dir)
    fences_path = _build(out)
    records = read_fences(fences_path)
    compiled = compile_fences(records, _area(records), PROFILES["copter"])
    plan_path = out / "onboard.plan"
    write_all(
        {
            plan_path: qgc_plan.dumps(
                qgc_plan.plan_document(
                    compiled.items,
                    breach_return=compiled.return_point,
                    sites=compiled.fence_sites(),
                )
            )
        }
    )
    out_console.print(
        f"compiled for a copter: {len(compiled.items)} items in {compiled.bytes_used}/"
        f"{compiled.profile.bytes} bytes -> {plan_path}"
    )
    from alphafence.sitl.find import find_sitl_binary

    binary = None if args.replay else find_sitl_binary()
    if binary is None:
        why = "--replay" if args.replay else "no ArduPilot SITL binary found"
        out_console.print(
            f"{why}: replaying a flight recorded from SITL through the monitor "
            "(`alphafence sitl --find` says how to get a binary)",
            soft_wrap=True,
        )
        return _replay(out, fences_path, records, args.map_server)
    return _fly(out, fences_path, records, compiled.items, binary, args.speedup)


def _build(out: Path) -> Path:
    from alphafence.fencefiles.atomic import write_all
    from alphafence.fencing.compare import compare_methods, telling_sites
    from alphafence.fencing.outputs import build_meta, render
    from alphafence.fencing.pipeline import BuildOptions, build_fences
    from alphafence.plots.compare import comparison_figure
    from alphafence.plots.fences import fence_map
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    scene = scene_path()
    rules = load_rules()
    db = read_database([scene], rules)
    opts = BuildOptions(method="alpha")
    result = build_fences(db.features, rules, opts)
    meta = build_meta(db, rules, opts)
    meta["note"] = NOTE
    paths = {k: out / f"fences.{k}" for k in ("geojson", "plan", "waypoints")}
    write_all(render(result.fences, meta, paths["geojson"], paths["plan"], paths["waypoints"]))
    fence_map(
        result.fences,
        result.sites,
        out / "fences.png",
        title="AlphaFence demo: alpha fences",
        note=NOTE,
    )
    out_console.print(f"[bold]AlphaFence demo[/] on {scene.name} ({NOTE})")
    out_console.print(
        f"{len(db.features)} restricted features -> {len(result.sites)} sites -> "
        f"{len(result.fences)} fences ({len(db.repaired)} invalid polygon(s) repaired)"
    )
    cmp = compare_methods(db.features, rules, list(METHODS), opts)
    out_console.print(stats_table(cmp, opts))
    comparison_figure(telling_sites(cmp), cmp.fences, out / "compare.png", note=NOTE)
    out_console.print(
        "wrote "
        + ", ".join(str(p) for p in [*paths.values(), out / "fences.png", out / "compare.png"])
    )
    return paths["geojson"]


def _area(records):
    """The operating area: the box around every fence of the scene."""
    import shapely

    return shapely.box(*shapely.GeometryCollection([r.geometry for r in records]).bounds)


def _fly(out, fences_path, records, items, binary, speedup) -> int:
    from alphafence.review.demo_flight import fly_at_fence

    flight = asyncio.run(
        _stopped_by_sigterm(
            fly_at_fence(
                fences_path,
                items,
                HOME,
                speedup=speedup,
                say=lambda line: out_console.print(line, soft_wrap=True),
                echo=_echo,
                binary=binary,
            )
        )
    )
    if flight is None:
        out_console.print("stopped (SIGTERM): SITL stopped, no flight written")
        return 143
    from alphafence.monitor.events import UtcClock

    trace = flight.trace
    clock = UtcClock.wall()  # the monitor's events were timed on this computer's clock
    _write_flight(out, records, trace, flight.events, trace.recorded, "SITL flight", clock)
    return 0


async def _stopped_by_sigterm(flight):
    """Await ``flight``; SIGTERM cancels it (SITL is stopped on the way out, as on Ctrl-C)
    and gives None."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    terminated = []
    loop.add_signal_handler(signal.SIGTERM, lambda: (terminated.append(1), task.cancel()))
    try:
        return await flight
    except asyncio.CancelledError:
        if not terminated:
            raise
        return None
    finally:
        loop.remove_signal_handler(signal.SIGTERM)


def _replay(out, fences_path, records, map_server=None) -> int:
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.review.replay import Trace, replay, speedup_options

    trace = Trace.read(trace_path())
    options = speedup_options(trace.speedup, enforce=True)
    out_console.print(f"replay of {trace.recorded}", soft_wrap=True)
    clock = trace.utc_clock()
    out_console.print(f"replay: UTC from the {clock.source}", soft_wrap=True)
    fences = FenceSet.from_geojson(fences_path)
    if map_server:
        events = asyncio.run(_replay_on_map(trace, fences, options, map_server, clock))
        if events is None:
            out_console.print("stopped before a page opened the map: no flight written")
            return 0
    else:
        events = replay(trace, fences, options, clock, replay=True)
        for e in events:
            _echo(e, prefix="replay ")
    title = f"REPLAY of {trace.recorded}"
    _write_flight(out, records, trace, events, title, "replay", clock, replay=True)
    return 0


async def _replay_on_map(trace, fences, options, address, clock):
    """The replay in real time with its live map served at ``address``: it starts when a
    page opens the map; the map stays up until Ctrl-C (or SIGTERM). The events, or None when
    stopped before a page opened the map."""
    from alphafence.livemap.server import open_live_map
    from alphafence.review.live_replay import replay_live

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    say = lambda line: out_console.print(line, soft_wrap=True)  # noqa: E731
    livemap, server = await open_live_map(fences, address, say)
    try:
        say("replay: starts when a page opens the live map; Ctrl-C to stop")
        opened = asyncio.ensure_future(livemap.opened.wait())
        stopping = asyncio.ensure_future(stop.wait())
        await asyncio.wait({opened, stopping}, return_when=asyncio.FIRST_COMPLETED)
        opened.cancel()
        if stop.is_set():
            return None
        done = await replay_live(
            trace,
            fences,
            options,
            [livemap],
            clock=clock,
            stop=stop,
            echo=lambda e: _echo(e, prefix="replay "),
            replay=True,
        )
        say(
            f"replay: {done.steps} positions checked ({done.coalesced} coalesced); the map stays "
            "up until Ctrl-C"
        )
        await stopping
        return done.events
    finally:
        await server.close()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


def _write_flight(out, records, trace, events, title, what, clock, **fields):
    import json

    from alphafence.fencefiles.atomic import write_all
    from alphafence.onboard.decode import decode_fence
    from alphafence.plots.flight import flight_figure
    from alphafence.review.replay import trace_tlog

    track = [(s.lon, s.lat) for s in trace.samples]
    flight_figure(
        records,
        decode_fence(trace.onboard_items) if trace.onboard_items else [],
        track,
        events,
        out / "flight.png",
        title=_wrap(f"AlphaFence demo: {title}"),
        note=NOTE,
    )
    write_all(
        {
            out / "events.jsonl": "".join(
                json.dumps(e) + "\n" for e in [_clock_event(trace, clock, fields), *events]
            ),
            out / "flight.trace.jsonl": trace.to_text(),
            out / "flight.tlog": trace_tlog(trace, clock),
        }
    )
    levels = [e["level"] for e in events if e["event"] == "level"]
    out_console.print(
        f"{what}: {len(trace.samples)} positions, alert levels {' -> '.join(levels) or 'none'}; "
        f"wrote {out / 'flight.png'}, {out / 'events.jsonl'}, {out / 'flight.trace.jsonl'}, "
        f"{out / 'flight.tlog'}",
        soft_wrap=True,
    )
    out_console.print(
        f"check the flight's log: alphafence check-flight {out / 'flight.tlog'} "
        f"--fences {out / 'fences.geojson'}",
        soft_wrap=True,
    )


def _clock_event(trace, clock, fields):
    """The events file's first line: where its UTC comes from, at the first sample."""
    t0 = trace.samples[0].t if trace.samples else None
    return clock.event(t0, **fields)


def _wrap(title, width=80):
    words, lines = title.split(), [""]
    for w in words:
        if lines[-1] and len(lines[-1]) + len(w) + 1 > width:
            lines.append("")
        lines[-1] = f"{lines[-1]} {w}".strip()
    return "\n".join(lines)


def _echo(event, prefix=""):
    kind = event["event"]
    prefix = f"{event['utc'][11:23]} {prefix}" if event.get("utc") else prefix
    if kind == "level":
        where = event.get("fence") or ""
        if event.get("onboard_only"):
            where += " (onboard fence only)"
        out_console.print(
            f"{prefix}monitor: {event['previous']} -> {event['level']} {where} "
            f"({event['reason']}, {event.get('distance_m')} m)",
            soft_wrap=True,
        )
    elif kind == "onboard_fence":
        kinds = ", ".join(f"{n} {what}" for what, n in event["fences"].items())
        out_console.print(
            f"{prefix}monitor: the vehicle's fence loaded: {event['items']} items ({kinds})",
            soft_wrap=True,
        )
    elif kind in ("action", "action_done", "action_failed", "onboard_failed"):
        detail = event.get("action") or event.get("error") or ""
        out_console.print(f"{prefix}monitor: {kind} {detail}", soft_wrap=True)
