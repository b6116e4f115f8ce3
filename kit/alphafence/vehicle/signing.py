"""Installing a MAVLink 2 signing key on a vehicle (SETUP_SIGNING), and confirming it.

The vehicle learns the key from a SETUP_SIGNING message (ArduPilot:
``GCS_MAVLINK::handle_setup_signing``): it stores the key, signs everything it sends from then
on and drops unsigned or wrongly signed messages on every link except channel 0 (SERIAL0,
"USB" on a flight controller, taken as physically secure) and RADIO_STATUS. It refuses a new
key while armed. An all-zero key and timestamp switch signing off. SETUP_SIGNING carries the
key in clear: send it over USB or loopback, never over a radio.

Key files and timestamps are :mod:`alphafence.vehicle.keys`.
"""

from __future__ import annotations

import asyncio

from alphafence.errors import VehicleError
from alphafence.vehicle.bridge import BridgeError, VehicleLink, is_signed, signature_matches
from alphafence.vehicle.keys import KEY_BYTES, signing_timestamp


class SigningSetupError(VehicleError):
    """The vehicle did not take the key (one line, saying what was seen)."""


async def install_key(
    url: str,
    new_key: bytes | None,
    current_key: bytes | None = None,
    timeout: float = 10.0,
) -> int:
    """Send SETUP_SIGNING (``new_key``, or None to switch signing off) to the autopilot at
    ``url`` and confirm it: the vehicle's heartbeats come signed with the new key (or unsigned
    after switching off). ``current_key`` signs the request when the vehicle already signs
    (it drops an unsigned SETUP_SIGNING except on its channel 0). Re-sent once a second until
    confirmed. Returns the vehicle's system id."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    heard = asyncio.Event()
    state = {"target": None, "texts": [], "confirmed": False, "signed_seen": False}
    key_bytes = bytes(KEY_BYTES) if new_key is None else bytes(new_key)

    def on_message(msg):
        if msg.get_type() == "STATUSTEXT":
            state["texts"].append(msg.text)
            return
        if msg.get_type() != "HEARTBEAT" or msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
            return
        if state["target"] is None:
            state["target"] = (msg.get_srcSystem(), msg.get_srcComponent())
        if (msg.get_srcSystem(), msg.get_srcComponent()) != state["target"]:
            return
        buf = bytes(msg.get_msgbuf())
        state["signed_seen"] |= is_signed(buf)
        if state["sent"]:
            ok = not is_signed(buf) if new_key is None else signature_matches(buf, key_bytes)
            if ok:
                state["confirmed"] = True
        heard.set()

    state["sent"] = False
    try:
        link = await VehicleLink(url, current_key, on_message, verify=False).open()
    except BridgeError as exc:
        raise SigningSetupError(str(exc)) from None
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    try:
        try:
            await asyncio.wait_for(heard.wait(), timeout)
        except asyncio.TimeoutError:
            why = link.closed or link.stats.diagnosis(current_key is not None)
            raise SigningSetupError(
                f"{url}: no autopilot heartbeat within {timeout:g} s" + (f" ({why})" if why else "")
            ) from None
        system, component = state["target"]
        ts = signing_timestamp()
        request = mavlink.MAVLink_setup_signing_message(
            system, component, list(key_bytes), 0 if new_key is None else ts
        )
        while not state["confirmed"]:
            refusal = [t for t in state["texts"] if "signing" in t.lower()]
            if refusal:
                raise SigningSetupError(f"{url}: the vehicle refused: {refusal[-1]}")
            if loop.time() > deadline:
                hint = ""
                if state["signed_seen"] and current_key is None:
                    hint = (
                        ": the vehicle already signs its messages, and drops an unsigned "
                        "SETUP_SIGNING; sign with the key it holds"
                    )
                raise SigningSetupError(f"{url}: the vehicle did not take the key{hint}")
            link.send(request)
            state["sent"] = True
            await asyncio.sleep(1.0)
        return system
    finally:
        await link.close()
