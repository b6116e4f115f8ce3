"""alphafence monitor: watch telemetry against every fence, predict breaches, alert, act."""

from __future__ import annotations

import asyncio
import signal

from rich.markup import escape

from alphafence.awareness.predict import Braking
from alphafence.awareness.reach import DEFAULT_ACCEL_MPS2
from alphafence.cli.common import (
    add_link_option,
    add_signing_option,
    add_trust_options,
    err_console,
    out_console,
    signing_key,
)
from alphafence.cli.options import (
    add_connect_option,
    non_negative,
    positive,
    sd_fence_kb,
    storage_profile,
)
from alphafence.cli.source_options import (
    add_source_options,
    live_options,
    source_line,
    start_fences,
)
from alphafence.errors import InputError, need
from alphafence.monitor.options import (
    ACTIONS,
    NOT_REROUTE,
    ONBOARD_MODES,
    REROUTE,
    MonitorOptions,
    RollingOptions,
)


def register(sub):
    """Add the ``monitor`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "monitor",
        help="watch a flight against the fences (companion computer)",
        description="Check every position against the full-resolution fences, predict breaches, "
        "alert the ground station and, with --enforce, brake/RTL/land.",
    )
    add_connect_option(p)
    p.add_argument(
        "--fences",
        metavar="FENCES.geojson",
        help="the full-resolution fences to watch: any fence file ('alphafence build' "
        "output, KML, OpenAir, a .plan...), signed (--trusted-key) or --allow-unsigned; "
        "with --source, optional (an offline copy, even an empty one: without it nothing is "
        "in force until the source's first complete answer)",
    )
    p.add_argument("--enforce", action="store_true", help="command the vehicle, not only alert")
    p.add_argument(
        "--horizon",
        type=positive("--horizon", "seconds"),
        default=15.0,
        metavar="S",
        help="look-ahead in seconds (default 15)",
    )
    p.add_argument(
        "--imminent-action",
        choices=ACTIONS,
        default="brake",
        help="with --enforce: brake (default), rtl, land, none, or reroute (fly around the "
        "fence with the route planner; brake if no route exists)",
    )
    p.add_argument(
        "--reroute-clearance",
        type=non_negative("--reroute-clearance", "metres"),
        default=20.0,
        metavar="M",
        help="distance a re-route keeps from every keep-out fence (default 20)",
    )
    p.add_argument(
        "--breach-action",
        type=_not_reroute("--breach-action"),
        choices=ACTIONS,
        default="rtl",
        help="with --enforce: what to do once inside a keep-out fence (or outside a keep-in "
        "one): rtl, brake, land or none (not reroute)",
    )
    p.add_argument(
        "--decel",
        type=positive("--decel", "m/s²"),
        default=2.5,
        metavar="M/S2",
        help="braking deceleration (default 2.5)",
    )
    p.add_argument(
        "--reaction",
        type=non_negative("--reaction", "seconds"),
        default=1.5,
        metavar="S",
        help="reaction time (default 1.5)",
    )
    p.add_argument(
        "--max-accel",
        type=positive("--max-accel", "m/s²"),
        default=DEFAULT_ACCEL_MPS2,
        metavar="M/S2",
        help="the vehicle's horizontal acceleration at most: far from fences, when the next "
        f"full check is due (default {DEFAULT_ACCEL_MPS2:g}; each position is still read "
        "against it)",
    )
    p.add_argument("--log", metavar="EVENTS.jsonl", help="append every event as a JSON line")
    p.add_argument(
        "--tlog",
        metavar="FLIGHT.tlog",
        help="record every MAVLink frame the vehicle sends as a telemetry log (as MAVProxy and "
        "QGroundControl write them), for 'alphafence check-flight'; the pymavlink link",
    )
    p.add_argument(
        "--until-disarmed",
        action="store_true",
        help="stop once the vehicle, having been armed, is disarmed (the flight is over); "
        "by default the monitor runs until Ctrl-C",
    )
    p.add_argument(
        "--map-server",
        metavar="HOST:PORT",
        help="serve a live map of the flight (the vehicle, its predicted path, the fences "
        "near it, its own fence, other aircraft, events) at http://HOST:PORT/; 127.0.0.1 is "
        "this computer only, any other address needs the token printed at start; read-only "
        "(needs aiohttp: the map extra)",
    )
    p.add_argument(
        "--basemap",
        metavar="EXTRACT.osm.pbf",
        help="with --map-server: draw the roads, water and place names of this OpenStreetMap "
        "extract beneath the live map, offline (within 10 km of the fences)",
    )
    p.add_argument(
        "--onboard",
        choices=ONBOARD_MODES,
        default="watch",
        help="watch (default): download the fence the vehicle holds at start and check it as a "
        "layer of its own (alerts, and --enforce, before the vehicle's own breach); rolling: "
        "also keep the vehicle's fence equal to the fences within its reach, compiled for "
        "--profile and re-uploaded (verified) in flight; off: not",
    )
    _add_rolling_options(p)
    p.add_argument(
        "--mavlink-traffic",
        action="store_true",
        help="also treat other MAVLink systems on the link as traffic (ADS-B always is)",
    )
    for flag, what in (
        ("--on-glitch", "a GPS glitch"),
        ("--on-stale", "telemetry older than 1 s"),
        ("--on-link-lost", "no telemetry for 5 s"),
    ):
        p.add_argument(
            flag,
            type=_not_reroute(flag),
            choices=ACTIONS,
            default="none",
            help=f"action (with --enforce) on {what}",
        )
    p.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    add_trust_options(p)
    add_signing_option(p)
    add_link_option(p)
    add_source_options(p, monitor=True)
    p.set_defaults(func=run)


def _add_rolling_options(p):
    """The options of ``--onboard rolling``: the storage compiled for and the reach."""
    from alphafence.mavlink.storage import PROFILES

    g = p.add_argument_group("rolling onboard fence (--onboard rolling)")
    g.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="the vehicle's fence storage (default: copter, 70 items in 560 bytes, on "
        "ArduPilot; px4, 64 items, on PX4)",
    )
    g.add_argument(
        "--sd-fence-kb",
        type=sd_fence_kb,
        metavar="N",
        help="with --profile navio2: the vehicle's BRD_SD_FENCE, 1-64 kB (default 64)",
    )
    g.add_argument(
        "--speed-limit",
        type=positive("--speed-limit", "m/s"),
        metavar="M/S",
        help="the fastest the vehicle flies (its WPNAV_SPEED, LOIT_SPEED; default 10)",
    )
    g.add_argument(
        "--reach-time",
        type=positive("--reach-time", "seconds"),
        metavar="S",
        help="the fence holds every fence the vehicle can reach in S seconds at the speed "
        "limit, and stop (default 30)",
    )


def _rolling_options(args) -> RollingOptions:
    """``RollingOptions`` from the rolling flags (refused without ``--onboard rolling``)."""
    given = [
        flag
        for flag, value in (
            ("--profile", args.profile),
            ("--sd-fence-kb", args.sd_fence_kb),
            ("--speed-limit", args.speed_limit),
            ("--reach-time", args.reach_time),
        )
        if value is not None
    ]
    if args.onboard != "rolling":
        if given:
            raise InputError(given[0], "sizes the rolling onboard fence: add --onboard rolling")
        return RollingOptions()
    extra = {}
    if args.speed_limit is not None:
        extra["speed_mps"] = args.speed_limit
    if args.reach_time is not None:
        extra["lookahead_s"] = args.reach_time
    given = args.profile is not None or args.sd_fence_kb is not None
    return RollingOptions(profile=storage_profile(args) if given else None, **extra)


def _not_reroute(flag):
    """An argparse type for actions that cannot be a re-route (breach and failsafes)."""

    def convert(text):
        if text == REROUTE:
            raise InputError(
                f"{flag} {REROUTE}", NOT_REROUTE.replace("imminent action", "--imminent-action")
            )
        return text

    return convert


def run(args) -> int:
    """Monitor the flight until Ctrl-C or SIGTERM; exit 0, or 3 when the link fails."""

    options = MonitorOptions(
        horizon_s=args.horizon,
        enforce=args.enforce,
        imminent_action=args.imminent_action,
        breach_action=args.breach_action,
        on_glitch=args.on_glitch,
        on_stale=args.on_stale,
        on_link_lost=args.on_link_lost,
        mavlink_traffic=args.mavlink_traffic,
        braking=Braking(reaction_s=args.reaction, decel_mps2=args.decel),
        max_accel_mps2=args.max_accel,
        reroute_clearance_m=args.reroute_clearance,
        onboard=args.onboard,
        rolling=_rolling_options(args),
    )
    need(*monitor_wants(options))
    if args.map_server:
        from alphafence.livemap.server import parse_address

        need(("aiohttp", "--map-server"))
        parse_address(args.map_server)
    if args.basemap and not args.map_server:
        raise InputError("--basemap", "is drawn on the live map: add --map-server HOST:PORT")
    if args.basemap:
        need(("osmium.filter", f"--basemap {args.basemap}"))
    fences = start_fences(args)
    args.key = signing_key(args)
    if args.log:
        from alphafence.monitor.eventlog import check_log_path

        check_log_path(args.log)
    if args.tlog:
        from alphafence.monitor.tlog import check_tlog_path
        from alphafence.vehicle.link import choose_link

        if choose_link(args.link) != "pymavlink":
            raise InputError("--tlog", "records the pymavlink link's frames: use --link pymavlink")
        check_tlog_path(args.tlog)
    return asyncio.run(_run(args, fences, options, live_options(args)))


def monitor_wants(options):
    """What the monitor needs beyond the base install and its link: scipy to re-route
    (``--imminent-action reroute``) and to compile the rolling onboard fence (it merges
    fences to fit the storage), checked before the flight rather than when first needed."""
    wants = []
    if options.imminent_action == REROUTE:
        wants.append(("scipy", "--imminent-action reroute"))
    if options.onboard == "rolling":
        wants.append(("scipy", "--onboard rolling"))
    return wants


async def _run(args, fences, options, live=None) -> int:
    from alphafence.monitor.run import run_monitor
    from alphafence.vehicle.link import LinkError

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    observers = []
    if args.until_disarmed:
        from alphafence.monitor.observe import UntilDisarmed

        observers.append(UntilDisarmed(stop))
    server = None
    if args.map_server:
        from alphafence.livemap.server import open_live_map

        basemap = None
        if args.basemap:  # read in a worker thread: an extract is seconds of work
            from alphafence.plots.osm_basemap import around, osm_basemap

            basemap = await asyncio.to_thread(osm_basemap, args.basemap, around(fences.records))
        livemap, server = await open_live_map(
            fences,
            args.map_server,
            lambda line: out_console.print(line, soft_wrap=True),
            basemap=basemap,
        )
        observers.append(livemap)
    mode = "enforcing" if options.enforce else "alerting only"
    out_console.print(
        f"monitoring {len(fences.records)} fences ({mode}); event times in UTC from this "
        "computer's clock, then monotonic seconds; Ctrl-C to stop"
    )
    if live is not None and not live.from_file:
        out_console.print("nothing is in force until the source's first complete answer: "
                          "no position is reported clear before it")  # fmt: skip
    try:
        monitor = await run_monitor(
            args.connect,
            fences,
            options,
            args.log,
            stop,
            echo=_echo,
            timeout=args.timeout,
            signing_key=args.key,
            link=args.link,
            tlog_path=args.tlog,
            observers=observers,
            live=live,
        )
    except LinkError as exc:
        err_console.print(f"alphafence monitor: error: {exc}", soft_wrap=True)
        return 3
    finally:
        if server is not None:
            await server.close()
    out_console.print(
        f"stopped after {monitor.engine.checks} checks"
        + (f"; telemetry log {args.tlog}" if args.tlog else "")
    )
    return 0


def _echo(event):
    when = f"{event.get('utc') or ''} {event['time']:.1f}".strip()
    if event["event"] == "level":
        out_console.print(
            f"{when} {event['previous']} -> {event['level']} {event.get('fence') or ''} "
            f"({event['reason']}, {event.get('distance_m')} m)"
        )
    elif event["event"] == "onboard_fence":
        kinds = ", ".join(f"{n} {what}" for what, n in event["fences"].items())
        out_console.print(
            f"{when} onboard fence: {event['items']} items ({kinds}), "
            f"{event['forbidden_beyond_m2']} m² forbidden beyond the full-resolution fences",
            soft_wrap=True,
        )
    elif event["event"] == "onboard_upload":
        out_console.print(
            f"{when} onboard fence uploaded ({event['reason']}): {event['items']} "
            f"items, {event['bytes']} B, {event['fences']} fences within {event['radius_m']} m, "
            f"verified in {event['seconds']} s",
            soft_wrap=True,
        )
    elif event["event"].startswith("source_"):
        out_console.print(f"{when} {escape(source_line(event))}", soft_wrap=True)
    elif event["event"] != "telemetry_resumed":
        out_console.print(
            f"{when} {event['event']} "
            f"{event.get('action') or event.get('reason') or event.get('error') or ''}",
            soft_wrap=True,
        )
