"""alphafence sitl: find a user-built ArduPilot SITL binary, or run one by hand."""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import re
import signal
import sys

from alphafence.cli.common import add_signing_option, signing_key
from alphafence.cli.options import add_connect_option
from alphafence.sitl.find import NOT_FOUND_HELP, find_sitl_binary


def register(sub):
    """Add the ``sitl`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "sitl",
        help="ArduPilot SITL helpers",
        description=(
            "Find a user-built ArduPilot SITL binary (--find, the default), list the named "
            "homes, run one copter SITL by hand (--home) until Ctrl-C, MAVLink on loopback "
            "(and on a serial device with --serial1), or fly a mission on a running SITL as a "
            "pilot would (--fly MISSION --connect URL: upload, arm, AUTO, until it lands)."
        ),
    )
    p.add_argument(
        "--find", action="store_true", help="print the arducopter binary found, or how to get one"
    )
    p.add_argument("--list-homes", action="store_true", help="list the named home locations")
    p.add_argument(
        "--home",
        metavar="NAME",
        help="run SITL at this named home (see --list-homes) or at lat,lon,alt,heading",
    )
    p.add_argument("--speedup", type=float, default=1.0, help="simulation speedup (default 1)")
    p.add_argument(
        "--instance", type=int, metavar="I", help="SITL instance number (default: a free one)"
    )
    p.add_argument(
        "--port", type=int, help="loopback UDP port SITL sends MAVLink to (default: a free one)"
    )
    p.add_argument(
        "--param-file",
        action="append",
        default=[],
        metavar="FILE",
        help="an extra defaults file loaded after the kit's (repeatable)",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        type=param_value,
        metavar="NAME=VALUE",
        help="set an ArduPilot parameter at start (repeatable), e.g. BRD_SD_FENCE=64 for the "
        "fence in a file (fence.stg in SITL's working directory)",
    )
    p.add_argument(
        "--no-wait",
        action="store_true",
        help="print the connection URLs at once instead of after the position estimate",
    )
    p.add_argument("--ready-timeout", type=float, default=120.0, metavar="S", help="default 120 s")
    p.add_argument(
        "--keep-dir", action="store_true", help="keep SITL's temporary working directory"
    )
    p.add_argument(
        "--serial1",
        type=sitl_device,
        metavar="uart:PATH:BAUD",
        help="with --home: MAVLink on SERIAL1 over this serial device as SITL takes it, e.g. "
        "one end of a socat pseudo-terminal pair (the other end is the kit's --connect PATH,BAUD)",
    )
    p.add_argument(
        "--fly",
        metavar="MISSION",
        help="fly this mission (.plan or .waypoints, e.g. from 'alphafence route') on the "
        "simulated vehicle at --connect: upload it, arm, AUTO, until it lands and disarms "
        "(refused on a vehicle without SIM_ parameters: a real one)",
    )
    add_connect_option(p, required=False)
    add_signing_option(p)
    p.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="with --fly: seconds to find the vehicle (default 30)",
    )
    p.set_defaults(func=run)


def sitl_device(text: str) -> str:
    """argparse type of ``--serial1``: a device as SITL's ``--serialN`` takes it.

    Examples
    --------
    >>> sitl_device("uart:/tmp/fc:57600")
    'uart:/tmp/fc:57600'
    """
    from alphafence.errors import InputError

    m = re.fullmatch(r"uart:([^:]+):(\d{3,7})", text.strip())
    if m is None:
        raise InputError(
            "--serial1", f"expected uart:PATH:BAUD (e.g. uart:/tmp/fc:57600), got {text!r}"
        )
    # SITL runs in a working directory of its own: a relative path is made absolute here
    return f"uart:{os.path.abspath(os.path.expanduser(m.group(1)))}:{m.group(2)}"


def param_value(text: str) -> tuple:
    """argparse type of ``--param``: ``NAME=VALUE`` -> ``(NAME, number)``.

    Examples
    --------
    >>> param_value("BRD_SD_FENCE=64")
    ('BRD_SD_FENCE', 64)
    """
    from alphafence.errors import InputError

    name, _, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        raise InputError("--param", f"expected NAME=VALUE, got {text!r}") from None
    if not (re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", name) and math.isfinite(number)):
        raise InputError("--param", f"expected NAME=VALUE (an ArduPilot parameter), got {text!r}")
    return name, int(number) if number.is_integer() and "." not in value else number


def run(args) -> int:
    """Print the SITL binary found (exit 1 with how to build one if none), list the homes,
    or run SITL at ``--home`` until Ctrl-C."""
    if args.list_homes:
        return list_homes()
    if args.fly is not None:
        return fly(args)
    if args.home is None:
        found = find_sitl_binary()
        if found is None:
            print(NOT_FOUND_HELP, file=sys.stderr)
            return 1
        print(found)
        return 0
    from alphafence.sitl.instance import SitlInstance

    sitl = SitlInstance(  # resolves the home first: a bad name is an InputError
        args.home,
        speedup=args.speedup,
        instance=args.instance,
        port=args.port,
        params=args.param_file,
        param_values=dict(args.param),
        keep_dir=args.keep_dir,
        serial1=args.serial1,
    )
    if find_sitl_binary() is None:
        print(NOT_FOUND_HELP, file=sys.stderr)
        return 1
    try:
        return asyncio.run(serve(sitl, wait=not args.no_wait, timeout=args.ready_timeout))
    except KeyboardInterrupt:
        print("alphafence sitl: stopped", file=sys.stderr)
        return 0


def fly(args) -> int:
    """Fly the mission ``args.fly`` on the simulated vehicle at ``args.connect``; exit 0 once
    it has landed and disarmed, 3 when the vehicle or the flight fails."""
    from alphafence.errors import InputError
    from alphafence.flights.mission_items import mission_rows
    from alphafence.sitl.fly import fly_mission
    from alphafence.vehicle.link import open_vehicle

    if args.connect is None:
        raise InputError("--fly", "needs --connect: the simulated vehicle's connection")
    rows = mission_rows(args.fly)
    key = signing_key(args)

    def say(text):
        print(text, flush=True)

    async def go():
        async with open_vehicle(args.connect, args.timeout, key, "pymavlink") as vehicle:
            return await fly_mission(vehicle, rows, say)

    try:
        asyncio.run(go())
    except KeyboardInterrupt:
        print("alphafence sitl: stopped (the vehicle flies on in its mode)", file=sys.stderr)
        return 130
    return 0


def list_homes() -> int:
    """Print the named homes, one a line; exit 0."""
    from alphafence.sitl.homes import load_homes

    for name, home in load_homes().items():
        print(f"{name:16} {home.arg():34} {home.description}")
    return 0


async def serve(sitl, *, wait: bool, timeout: float) -> int:
    """Start ``sitl``, print how to connect (after its position estimate when ``wait``), and
    wait for it to exit (exit status 1) or for Ctrl-C or SIGTERM (SITL stopped, exit 0)."""
    from alphafence.sitl.cmdline import copter_defaults

    def say(text):
        print(text, flush=True)

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):  # also when started with & (SIGINT ignored)
        loop.add_signal_handler(sig, stop.set)
    async with sitl:
        say(f"SITL {sitl.binary}  pid {sitl.pid}  instance {sitl.instance}")
        say(f"home {sitl.home.name} {sitl.home.arg()}  speedup {sitl.speedup:g}")
        say(f"working directory {sitl.workdir}  (log {sitl.log_path})")
        if copter_defaults(sitl.binary) is None:
            say(
                "note: no ArduPilot tree found beside the binary, so ArduPilot's copter defaults "
                "are not loaded and arming will fail (accelerometer calibration)"
            )
        if wait:
            say("waiting for a position estimate ...")
            state = await _until(sitl.wait_ready(timeout), stop)
            if state is None:
                say("stopped")
                return 0
            lat, lon, alt = state.position
            say(f"ready: position {lat:.7f},{lon:.7f} alt {alt:.1f} m")
        if sitl.serial1:
            say(f"SERIAL1:            {sitl.serial1} (MAVLink 2)")
        say(f"MAVSDK:             {sitl.connection_url}")
        say(f"pymavlink/MAVProxy: {sitl.pymavlink_url}   (one client at a time)")
        say("Ctrl-C stops SITL")
        code = await _until(sitl.process.wait(), stop)
        if code is None:
            say("stopped")
            return 0
        say(f"SITL exited with code {code}")
        print(sitl.log_tail(), file=sys.stderr)
        return 1


async def _until(coro, stop: asyncio.Event):
    """``await coro``, or None as soon as ``stop`` is set (``coro`` cancelled)."""
    task = asyncio.ensure_future(coro)
    stopping = asyncio.ensure_future(stop.wait())
    await asyncio.wait({task, stopping}, return_when=asyncio.FIRST_COMPLETED)
    stopping.cancel()
    if task.done():
        return task.result()
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    return None
