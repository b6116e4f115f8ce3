"""alphafence signing: MAVLink 2 signing keys, and installing one on a vehicle (SETUP_SIGNING,
as MAVProxy's ``signing`` module does): who may talk to the vehicle.

Not fence signatures (``alphafence bundle``, ``--trusted-key``), which say who made the
fences."""

from __future__ import annotations

import asyncio

from alphafence.cli.common import add_signing_option, err_console, out_console, signing_key
from alphafence.cli.options import add_connect_option
from alphafence.errors import InputError, need


def register(sub):
    """Add the ``signing`` verb (keygen, setup, remove) to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "signing",
        help="MAVLink 2 link signing keys (who may talk to the vehicle)",
        description="MAVLink 2 link signing: who may talk to the vehicle. 'signing keygen' "
        "writes a secret key that the vehicle and the kit share; 'signing setup' installs it "
        "on the vehicle. Once a vehicle holds a key it signs what it sends and ignores "
        "unsigned commands on its telemetry links; upload, download and monitor then need "
        "--signing-key KEY_FILE. This is not the fence signature of 'alphafence bundle' "
        "('bundle keygen', --trusted-key): that key pair says who made the fences.",
    )
    verbs = p.add_subparsers(dest="signing_verb", required=True, metavar="ACTION")
    k = verbs.add_parser(
        "keygen",
        help="write a new random link key file (mode 0600; not the fences' bundle key)",
    )
    k.add_argument("key", metavar="KEY_FILE", help="the key file to write")
    s = verbs.add_parser(
        "setup",
        help="install KEY_FILE's key on the vehicle",
        description="Sends SETUP_SIGNING (the key in clear: do it over USB or loopback, never "
        "a radio) and confirms that the vehicle then signs with it. ArduPilot refuses while "
        "armed.",
    )
    add_connect_option(s)
    s.add_argument("--key", required=True, metavar="KEY_FILE", help="the key to install")
    add_signing_option(s)
    s.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    r = verbs.add_parser("remove", help="switch signing off on the vehicle (needs its current key)")
    add_connect_option(r)
    add_signing_option(r)
    r.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="seconds to find the vehicle"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    """Write a key, or install or remove one on the vehicle; exit 0, or 3 when the vehicle
    refuses or does not confirm (a :class:`~alphafence.errors.VehicleError`)."""
    from alphafence.vehicle.keys import key_id, load_key, write_new_key

    if args.signing_verb == "keygen":
        key = write_new_key(args.key)
        out_console.print(f"wrote {args.key} (key {key_id(key)}; keep it secret)")
        return 0
    need(("pymavlink", f"signing {args.signing_verb}"))
    current = signing_key(args)
    if args.signing_verb == "setup":
        new = load_key(args.key)
    else:
        if current is None:
            raise InputError("--signing-key", "removing signing needs the vehicle's current key")
        new = None
    _warn_if_remote(args.connect)
    return asyncio.run(_install(args, new, current))


async def _install(args, new, current) -> int:
    from alphafence.vehicle.keys import key_id
    from alphafence.vehicle.signing import install_key

    system = await install_key(args.connect, new, current, args.timeout)
    if new is None:
        out_console.print(f"vehicle {system}: signing switched off (it sends unsigned messages)")
    else:
        out_console.print(f"vehicle {system}: now signs with key {key_id(new)} (confirmed)")
    return 0


def _warn_if_remote(url: str) -> None:
    from alphafence.vehicle.endpoints import USB_BAUD, EndpointError, default_baud, parse_endpoint

    try:
        ep = parse_endpoint(url)
    except EndpointError:
        return  # install_key reports it
    if ep.kind == "serial":
        where = None if default_baud(ep.device) == USB_BAUD else ep.device
        what = "if it is a telemetry radio, anyone listening"
    else:
        where = None if ep.host in ("127.0.0.1", "localhost", "::1", "0.0.0.0") else ep.host
        what = "anyone listening on that link"
    if where is not None:
        err_console.print(
            f"[yellow]warning:[/] SETUP_SIGNING carries the key in clear to {where}: {what} "
            "learns it (use USB or loopback)",
            soft_wrap=True,
        )
