"""The vehicle link in pure Python: pymavlink's codec on asyncio, nothing native.

It exists wherever Python does (a Navio2's 32-bit Raspberry Pi OS included, where MAVSDK 4 has
no wheel) and offers the monitor, the fence transfer and the parameter code what the MAVSDK
link offers, under the same names (``telemetry``, ``action``, ``param``, ``mission_raw`` and
the kit's own methods of :class:`~alphafence.vehicle.link.Vehicle`), so they run one code path.

Lean by construction: the messages nobody follows are framed and dropped without being
decoded (:class:`Bus` tells the link which ids are wanted: their frames alone are checked and
unpacked, the others are dropped from their header), so at 50 Hz telemetry the link costs
little more than the positions it delivers. Signing is the link's own (no bridge): with a
key every message sent is signed and every message received must be.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import defaultdict
from collections.abc import Callable

from alphafence.geo.coords import to_e7
from alphafence.mavlink import ids
from alphafence.mavlink.autopilots import ARDUPILOT, autopilot_of
from alphafence.mavlink.commands import command_long_fields
from alphafence.vehicle.base import LinkError, Vehicle
from alphafence.vehicle.bridge import MESSAGE_IDS, BridgeError, VehicleLink
from alphafence.vehicle.mission_client import MissionClient
from alphafence.vehicle.pymavlink_plugins import Action, MissionRaw, Param, Telemetry
from alphafence.vehicle.values import Message

AUTOPILOT_COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1
HEARTBEAT_S = 1.0  # our GCS heartbeat
BEAT_EARLY, BEAT_LATE = 0.5, 1.5  # with the autopilot's, if at least half a period since ours;
# alone after one and a half periods without one of the autopilot's
CONNECTED_S = 3.0  # no autopilot heartbeat for this long: not connected
COMMAND_RETRY_S = 1.0
COMMAND_TRIES = 3
ALWAYS = ("HEARTBEAT", "STATUSTEXT")  # decoded whoever follows them


class Bus:
    """Decoded messages to whoever follows them: one bounded queue per subscriber.

    A full queue drops its oldest message (a slow reader sees the latest telemetry, never an
    unbounded backlog)."""

    def __init__(self, message_id: Callable[[str], int | None] = lambda name: None):
        self._subs: dict[str, list[tuple]] = defaultdict(list)  # name -> (queue, handle)
        self._id = message_id
        self.wanted: set[str] = set()  # message types the link decodes
        self.wanted_ids: set[int] = set()  # and their ids, for the link's filter
        for name in ALWAYS:
            self._want(name)

    def _want(self, name: str) -> None:
        self.wanted.add(name)
        if (msgid := self._id(name)) is not None:
            self.wanted_ids.add(msgid)

    def _unwant(self, name: str) -> None:
        self.wanted.discard(name)
        if (msgid := self._id(name)) is not None:
            self.wanted_ids.discard(msgid)

    def alone(self, name: str) -> bool:
        """Whether one subscriber alone follows ``name`` messages (a fast decoder may then
        take them: :meth:`VehicleLink.fast <alphafence.vehicle.bridge.VehicleLink.fast>`)."""
        return len(self._subs.get(name, ())) == 1

    def publish(self, msg) -> None:
        """Hand ``msg`` to every subscriber of its type: its ``handle`` first, if it has one
        (which may take the message), else its queue."""
        for queue, handle in self._subs.get(msg.get_type(), ()):
            if handle is not None and handle(msg):
                continue
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(msg)

    @contextlib.contextmanager
    def subscribe(self, *names: str, maxsize: int = 256, handle=None):
        """``with bus.subscribe("MISSION_ACK", ...) as queue:`` the messages of those types
        that arrive while the block runs.

        ``handle(msg) -> bool``, if given, sees each message first, as it is parsed (no task
        wakes up for it): a transfer answers the vehicle's request there at once; the messages
        it returns True for are not queued."""
        queue: asyncio.Queue = asyncio.Queue(maxsize)
        entry = (queue, handle)
        for name in names:
            self._subs[name].append(entry)
            self._want(name)
        try:
            yield queue
        finally:
            for name in names:
                self._subs[name].remove(entry)
                if not self._subs[name] and name not in ALWAYS:
                    del self._subs[name]
                    self._unwant(name)

    async def stream(self, *names: str, maxsize: int = 64):
        """Every message of those types from now on (an async generator)."""
        with self.subscribe(*names, maxsize=maxsize) as queue:
            while True:
                yield await queue.get()


class PymavlinkVehicle(Vehicle):
    """A connected autopilot over :class:`~alphafence.vehicle.bridge.VehicleLink`.

    Parameters
    ----------
    url : str
        A connection :func:`~alphafence.vehicle.endpoints.parse_endpoint` reads: a serial
        port (``/dev/ttyACM0``, ``/dev/ttyUSB0,57600``, ``COM3``), UDP or TCP.
    signing_key : bytes, optional
        32 bytes: sign what is sent, accept only what is signed with it.

    Attributes
    ----------
    target : tuple of int
        The autopilot's (system id, component id), once :meth:`connect` found it.
    mav_type : int
        Its HEARTBEAT's ``type`` (copter, plane, rover: which modes it has).
    """

    kind = "pymavlink"

    def __init__(self, url: str, signing_key: bytes | None = None):
        super().__init__(url)
        self.bus = Bus(MESSAGE_IDS.get)
        self.link = VehicleLink(url, signing_key, self.bus.publish)
        self.link.wanted_ids = self.bus.wanted_ids  # the rest is dropped unread
        self.target = (0, AUTOPILOT_COMPONENT)
        self.mav_type = ids.MAV_TYPE_QUADROTOR
        self.last_heartbeat = -1e9
        self.mission = MissionClient(self)
        self.telemetry = Telemetry(self)
        self.action = Action(self)
        self.param = Param(self)
        self.mission_raw = MissionRaw(self)
        self._tasks: list[asyncio.Task] = []
        self._follow = None  # the subscription to the autopilot's heartbeats, once connected
        self._beat_t = -1e9  # when our last heartbeat went
        self._beat_timer: asyncio.TimerHandle | None = None
        self._heartbeat = self.link.mav.heartbeat_encode(  # packed anew each time it goes
            ids.MAV_TYPE_GCS, ids.MAV_AUTOPILOT_INVALID, 0, 0, ids.MAV_STATE_ACTIVE
        )

    async def connect(self, timeout: float) -> PymavlinkVehicle:
        """Open the link and wait for the autopilot's heartbeat.

        Raises
        ------
        LinkError
            When the link cannot be opened or no autopilot is heard within ``timeout``.
        """
        try:
            await self.link.open()
        except BridgeError as exc:
            raise LinkError(str(exc)) from None
        self._beat()
        with self.bus.subscribe("HEARTBEAT") as queue:
            try:
                await asyncio.wait_for(self._autopilot(queue), timeout)
            except asyncio.TimeoutError:
                why = f"{self.url}: no autopilot answered within {timeout:g} s"
                diagnosis = self.link.closed or self.link.stats.diagnosis(self.link.key is not None)
                await self.close()
                raise LinkError(why + (f" ({diagnosis})" if diagnosis else "")) from None
        self._follow = self.bus.subscribe("HEARTBEAT", maxsize=1, handle=self._autopilot_heard)
        self._follow.__enter__()
        await self.start()
        return self

    async def _autopilot(self, queue):
        while True:
            msg = await queue.get()
            if msg.autopilot != ids.MAV_AUTOPILOT_INVALID:
                self._heard(msg)
                return

    def _heard(self, msg):
        self.autopilot = autopilot_of(msg.autopilot) or ARDUPILOT
        self.target = (msg.get_srcSystem(), msg.get_srcComponent())
        self.mav_type = int(msg.type)
        self.last_heartbeat = time.monotonic()

    def _autopilot_heard(self, msg) -> bool:
        """Each HEARTBEAT as it is parsed: the autopilot's, for :meth:`is_connected`; ours
        goes out with it when one is due (no task wakes up for either)."""
        if (msg.get_srcSystem(), msg.get_srcComponent()) == self.target:
            self.last_heartbeat = now = time.monotonic()
            if now - self._beat_t >= BEAT_EARLY * HEARTBEAT_S:
                self._beat(BEAT_LATE * HEARTBEAT_S)
        return True

    def _beat(self, fallback_s: float = HEARTBEAT_S) -> None:
        """Send our GCS heartbeat, and the next one in ``fallback_s`` unless the autopilot's
        next heartbeat brings it first (a timer, cancelled: nothing wakes for it)."""
        self.link.send(self._heartbeat)
        self._beat_t = time.monotonic()
        if self._beat_timer is not None:
            self._beat_timer.cancel()
        self._beat_timer = asyncio.get_running_loop().call_later(fallback_s, self._beat)

    async def close(self):
        """Stop the vehicle's tasks and close the link."""
        await super().close()
        if self._beat_timer is not None:
            self._beat_timer.cancel()
            self._beat_timer = None
        if self._follow is not None:
            self._follow.__exit__(None, None, None)
            self._follow = None
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks = []
        await self.link.close()

    # -- the kit's own methods (see Vehicle) ------------------------------------------
    def from_autopilot(self, msg) -> bool:
        """Whether ``msg`` came from the autopilot this link talks to."""
        return (msg.get_srcSystem(), msg.get_srcComponent()) == self.target

    async def status_texts(self):
        """The autopilot's STATUSTEXTs (an async generator)."""
        async for msg in self.bus.stream("STATUSTEXT"):
            if msg.get_srcSystem() == self.target[0]:
                yield msg

    async def messages(self, name: str):
        """Every ``name`` message on the link, from any system, as a :class:`Message`."""
        async for msg in self.bus.stream(name):
            fields = msg.to_dict()
            fields.pop("mavpackettype", None)
            yield Message(name, msg.get_srcSystem(), msg.get_srcComponent(), fields)

    async def command_long(self, command: int, *params, target_component=AUTOPILOT_COMPONENT):
        """Send a COMMAND_LONG and return the COMMAND_ACK's ``result`` (sent again up to
        :data:`COMMAND_TRIES` times without an answer; TimeoutError after that)."""
        fields = command_long_fields(self.target[0], target_component, command, *params)

        def encode(attempt):
            fields["confirmation"] = attempt
            return self.link.mav.command_long_encode(**fields)

        return await self._acked(command, encode)

    async def command_int(self, command: int, frame: int, params, lat: float, lon: float, alt):
        """Send a COMMAND_INT (``params``: param1-4; the position as MAVLink's integers) and
        return the COMMAND_ACK's ``result``, as :meth:`command_long`."""
        p = [float(v) for v in params] + [0.0] * (4 - len(params))
        sysid, compid = self.target
        msg = self.link.mav.command_int_encode(
            sysid, compid, frame, command, 0, 0, *p, to_e7(lat), to_e7(lon), float(alt)
        )
        return await self._acked(command, lambda attempt: msg)

    async def _acked(self, command, encode) -> int:
        sysid = self.target[0]
        with self.bus.subscribe("COMMAND_ACK", maxsize=16) as queue:
            for attempt in range(COMMAND_TRIES):
                self.link.send(encode(attempt))
                deadline = time.monotonic() + COMMAND_RETRY_S
                while (left := deadline - time.monotonic()) > 0:
                    try:
                        ack = await asyncio.wait_for(queue.get(), left)
                    except asyncio.TimeoutError:
                        break
                    if ack.command != command or ack.get_srcSystem() != sysid:
                        continue
                    if ack.result == ids.MAV_RESULT_IN_PROGRESS:
                        deadline = time.monotonic() + COMMAND_RETRY_S
                        continue
                    return int(ack.result)
        raise TimeoutError(f"no answer to command {command}")

    def send_command_long(self, command: int, *params, target_component=AUTOPILOT_COMPONENT):
        """Send a COMMAND_LONG without waiting for its answer."""
        fields = command_long_fields(self.target[0], target_component, command, *params)
        self.link.send(self.link.mav.command_long_encode(**fields))

    async def system_id(self) -> int:
        """The autopilot's MAVLink system id."""
        return self.target[0]

    async def send_status_text(self, severity: int, text: str) -> None:
        """A STATUSTEXT to the ground station (``MAV_SEVERITY``)."""
        self.link.send(self.link.mav.statustext_encode(severity, text.encode()[:50]))

    async def upload_geofence(self, items) -> None:
        """Upload ``items`` (FenceItems) as the fence; TransferFailed on failure."""
        await self.mission.upload(items, ids.MAV_MISSION_TYPE_FENCE)

    async def download_geofence(self, max_items: int | None = None) -> list:
        """The fence's raw items ([] when there is none); TransferFailed on failure."""
        return await self.mission.download(ids.MAV_MISSION_TYPE_FENCE, max_items)

    async def is_connected(self) -> bool:
        """Whether the autopilot's heartbeat was heard within :data:`CONNECTED_S`."""
        return time.monotonic() - self.last_heartbeat < CONNECTED_S

    def link_diagnosis(self) -> str:
        """Why the vehicle may be silent ('' when nothing points to a reason)."""
        return self.link.closed or self.link.stats.diagnosis(self.link.key is not None)

    def link_stats(self):
        """What the link accepted, sent and dropped
        (:class:`~alphafence.vehicle.bridge.LinkStats`)."""
        return self.link.stats
