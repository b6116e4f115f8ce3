"""What every vehicle link offers (:class:`Vehicle`) and the errors of opening one.

The links themselves: :mod:`alphafence.vehicle.link` (MAVSDK, and the choice of link) and
:mod:`alphafence.vehicle.pymavlink_link`.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque

from alphafence.errors import VehicleError


class LinkError(VehicleError):
    """The vehicle could not be reached, or went away."""


class NoLinkError(VehicleError):
    """The link asked for (or any link, for ``auto``) is not installed."""


class Vehicle:
    """A connected autopilot, whichever link: what the kit calls on it.

    MAVSDK-named plugins (``telemetry``, ``action``, ``param``, ``mission_raw``: the methods
    the kit uses, same names and values on both links) and the kit's own methods below.

    Attributes
    ----------
    url : str
        The connection as the operator gave it (for messages).
    kind : str
        ``"mavsdk"`` or ``"pymavlink"``.
    texts : deque
        ``(monotonic time, text)`` of the last 50 STATUSTEXTs.
    bridge : SigningBridge or None
        The loopback signing bridge of a signed MAVSDK link.
    autopilot : str
        ``"ardupilot"`` or ``"px4"``, from the autopilot's HEARTBEAT (another autopilot is
        taken as ArduPilot, as before the kit knew PX4).
    """

    kind = ""
    autopilot = "ardupilot"

    def __init__(self, url):
        self.url = url
        self.texts: deque = deque(maxlen=50)  # (monotonic time, text)
        self.bridge = None
        self._task = None

    async def start(self):
        """Start collecting the vehicle's STATUSTEXTs."""
        self._task = asyncio.create_task(self._collect_texts())

    async def close(self):
        """Stop collecting STATUSTEXTs."""
        if self._task:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
            self._task = None

    async def _collect_texts(self):
        async for st in self.telemetry.subscribe_status_text():
            self.texts.append((time.monotonic(), st.text))

    async def texts_since(self, t0: float, settle: float = 0.3):
        """STATUSTEXTs received after ``t0`` (waits briefly: they trail the ACK by a few ms)."""
        await asyncio.sleep(settle)
        return [text for t, text in self.texts if t >= t0]

    # -- the kit's own methods, each link's ------------------------------------------
    async def messages(self, name: str):
        """Every ``name`` message on the link, from any system, as
        :class:`~alphafence.vehicle.values.Message` (an async generator)."""
        raise NotImplementedError
        yield  # pragma: no cover

    async def command_long(self, command: int, *params, target_component=1) -> int:
        """Send a COMMAND_LONG; the COMMAND_ACK's ``result``."""
        raise NotImplementedError

    def send_command_long(self, command: int, *params, target_component=1) -> None:
        """Send a COMMAND_LONG without waiting for its answer."""
        raise NotImplementedError

    async def system_id(self) -> int:
        """The autopilot's MAVLink system id."""
        raise NotImplementedError

    async def send_status_text(self, severity: int, text: str) -> None:
        """A STATUSTEXT to the ground station (``MAV_SEVERITY``)."""
        raise NotImplementedError

    async def upload_geofence(self, items) -> None:
        """Upload FenceItems as the fence (TransferFailed on failure)."""
        raise NotImplementedError

    async def download_geofence(self, max_items: int | None = None) -> list:
        """The fence's raw items, [] when there is none (TransferFailed on failure)."""
        raise NotImplementedError

    async def is_connected(self) -> bool:
        """Whether the vehicle is still heard."""
        raise NotImplementedError

    def link_diagnosis(self) -> str:
        """Why the vehicle may be silent ('' when nothing points to a reason)."""
        return ""

    def link_stats(self):
        """What the signed link accepted, sent and dropped
        (:class:`~alphafence.vehicle.bridge.LinkStats`), or None for an unsigned MAVSDK link."""
        return None
