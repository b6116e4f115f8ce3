"""A scripted MAVLink peer that speaks ArduPilot's fence protocol, for fault-injection tests.

``FakeVehicle`` is an asyncio UDP peer (system 1, component 1, an ArduPilot quadrotor) that
MAVSDK accepts as an autopilot: it sends HEARTBEAT at 1 Hz and answers the AUTOPILOT_VERSION
request MAVSDK makes on discovery (with the MISSION_INT capability, without which MAVSDK
refuses mission transfers). MAVSDK listens (``udpin://127.0.0.1:PORT``); the fake sends to
that port, and MAVSDK answers to wherever the fake's datagrams come from.

The fence transfer follows ArduPilot's MissionItemProtocol / MissionItemProtocol_Fence /
AC_PolyFence_loader (mission type FENCE only):

* upload: MISSION_COUNT -> MISSION_REQUEST (id 40, not _INT) per item -> MISSION_ITEM_INT ->
  MISSION_ACK. A count over capacity is refused at once (NO_SPACE, "Only 70 items are
  supported"); the items are validated and sized when the last one arrives (ERROR, "Fence
  exceeds storage size", "Fence validation failed", ...). An item with the wrong sequence
  number is answered MISSION_ACK(INVALID_SEQUENCE) and the transfer goes on; an item while no
  upload is under way is answered MISSION_ACK(ERROR). A stalled client is re-asked every
  second and the upload cancelled 8 s after the last item (STATUSTEXT "Fence upload timeout",
  then MISSION_ACK(OPERATION_CANCELLED)). A failed upload leaves the previous fence in place.
* download: MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT -> MISSION_ITEM_INT
  (frame GLOBAL, exact 1e-7 degrees); while an upload is under way both are refused with
  MISSION_ACK(DENIED).
* STATUSTEXTs trail the MISSION_ACK by a few milliseconds, as ArduPilot's queued texts do.

Capacity: 70 items and 560 bytes (a Copter): header 4 bytes, a polygon 2 + 8 per vertex, a
circle 13, the return point 9, end marker 1 (alphafence.mavlink.storage's ``storage_bytes`` layout).

Parameters, arming and reboots, as ArduPilot has them: PARAM_REQUEST_READ and PARAM_SET of the
names in ``params`` are answered with PARAM_VALUE (integers as INT16, like BRD_SD_FENCE; other
names get no answer); the heartbeat carries the safety-armed flag while ``armed``;
MAV_CMD_REQUEST_MESSAGE(SYSTEM_TIME) is answered with the time since boot; and
MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN (param1 1) is refused (FAILED) while armed, else acknowledged,
after which the fake goes silent for ``reboot_seconds`` and boots again: its boot clock starts
over and, with ``BRD_SD_FENCE`` above 0, its fence storage becomes that file's
(min(kB * 1024, 65535) bytes, an item per 8 bytes), as AC_PolyFence_loader::init sizes it.

Faults (``Faults``) are scripted and deterministic: the numbered or seeded-random loss of
mission-protocol messages (only MISSION_* messages are numbered and subject to loss, so that
heartbeats and MAVSDK's discovery traffic cannot shift the numbering), late (re-ordered)
messages, duplicated and out-of-order requests, NACKs, a stall and a disconnect; a fence
stored other than it was received and acknowledged (an item changed or left out), and a
parameter that keeps its own value whatever is set (answered with that value). Everything
the fake sees, sends and loses is recorded in ``FakeVehicle.log``.

No threads and no mavutil: the kit's pymavlink-over-UDP endpoint
(``alphafence.mavlink.udp.MavlinkDatagrams``) parses and encodes with the fake's own pymavlink
codec; the faults are applied here, around it.
"""

from __future__ import annotations

import asyncio
import os
import random
import socket
import time
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field, replace

from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.mavlink.udp import MavlinkDatagrams

SYSTEM_ID = 1
COMPONENT_ID = 1
FENCE = mav.MAV_MISSION_TYPE_FENCE

POLYGON_INCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION  # 5001
POLYGON_EXCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION  # 5002
CIRCLE_INCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION  # 5003
CIRCLE_EXCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION  # 5004
RETURN_POINT = mav.MAV_CMD_NAV_FENCE_RETURN_POINT  # 5000
POLYGONS = (POLYGON_INCLUSION, POLYGON_EXCLUSION)
CIRCLES = (CIRCLE_INCLUSION, CIRCLE_EXCLUSION)
GLOBAL_FRAMES = (
    mav.MAV_FRAME_GLOBAL,
    mav.MAV_FRAME_GLOBAL_INT,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
)
CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)
MISSION_MESSAGES = frozenset(
    {
        "MISSION_COUNT",
        "MISSION_REQUEST",
        "MISSION_REQUEST_INT",
        "MISSION_REQUEST_LIST",
        "MISSION_ITEM",
        "MISSION_ITEM_INT",
        "MISSION_ACK",
        "MISSION_CLEAR_ALL",
    }
)
TEXT_DELAY = 0.005  # STATUSTEXT after the ACK, as ArduPilot's deferred texts arrive


def free_udp_port() -> int:
    """A UDP port on loopback that nothing listens on right now (for MAVSDK's udpin).

    Taken below Linux's ephemeral range (32768 up), from a thousand ports of this pytest-xdist
    worker's own: a port the system handed out as free would go to the next socket bound to
    port 0 (another worker's fake vehicle) before the kit binds it."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:]
    base = 20000 + (int(worker) % 12 if worker.isdigit() else 0) * 1000
    pick = random.SystemRandom()
    for _ in range(200):
        port = base + pick.randrange(1000)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:  # in use: another
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass(frozen=True)
class StoredItem:
    """One fence item as the vehicle keeps it (x = latitude, y = longitude, 1e-7 degrees)."""

    command: int
    param1: float
    x: int
    y: int

    @property
    def lat(self) -> float:
        return self.x / 1e7

    @property
    def lon(self) -> float:
        return self.y / 1e7

    @classmethod
    def of(cls, item) -> StoredItem:
        """From anything with command, param1, lon, lat (e.g. kit's FenceItem)."""
        if isinstance(item, StoredItem):
            return item
        return cls(
            int(item.command),
            float(item.param1),
            int(round(item.lat * 1e7)),
            int(round(item.lon * 1e7)),
        )


def storage_bytes(items) -> int:
    """Bytes of fence storage the items need (the layout of alphafence.mavlink.storage's storage_bytes)."""
    total = 4 + 1  # header, end marker
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in POLYGONS:
            n = max(int(it.param1), 1)
            total += 2 + 8 * n
            i += n
            continue
        total += 9 if it.command == RETURN_POINT else 13
        i += 1
    return total


def validate(items) -> str | None:
    """AC_PolyFence_loader::validate_fence: None, or the vehicle's complaint."""
    expected = 0  # vertices still expected in the current polygon
    count = 0
    kind = None
    seen_return = False
    for it in items:
        if it.command in POLYGONS:
            n = int(it.param1)
            if n < 3:
                return f"Invalid vertex count ({n})"
            if expected == 0:
                expected = count = n
                kind = it.command
            elif it.command != kind:
                return f"Received incorrect vertex type (want={kind} got={it.command})"
            elif n != count:
                return f"Unexpected vertex count want={count} got={n}\n"  # sic
            expected -= 1
        elif expected:
            return f"Received incorrect type (want={kind} got={it.command})"
        elif it.command in CIRCLES:
            if not it.param1 > 0:
                return "Non-positive circle radius"
        elif it.command == RETURN_POINT:
            if seen_return:
                return "Multiple return points"
            seen_return = True
        if not (-900_000_000 <= it.x <= 900_000_000 and -1_800_000_000 <= it.y <= 1_800_000_000):
            return "Bad lat or lon"
    if expected:
        return "Incorrect item count"
    return None


@dataclass
class Faults:
    """What goes wrong, scripted. Message numbers count mission-protocol (MISSION_*) messages
    only, from 0, separately per direction, over the fake's whole life (uploads and the
    downloads after them)."""

    drop_in: Collection[int] = ()  # incoming mission messages lost on the way in
    drop_out: Collection[int] = ()  # outgoing mission messages lost on the way out
    loss_in: float = 0.0  # fraction of incoming mission messages lost at random
    loss_out: float = 0.0  # fraction of outgoing mission messages lost at random
    seed: int = 0  # for the random loss
    delay_out: Mapping[int, float] = field(default_factory=dict)  # outgoing number -> s late
    duplicate_requests: Collection[int] = ()  # item numbers whose MISSION_REQUEST goes twice
    # before requesting item k, first request item j ({k: j}); j > k asks ahead, j < k asks again
    # for an item already received (both out of order)
    extra_requests: Mapping[int, int] = field(default_factory=dict)
    nack_count: int | None = None  # answer MISSION_COUNT with this MAV_MISSION_RESULT
    nack_item: tuple[int, int] | None = None  # (item number, MAV_MISSION_RESULT) refuse it
    nack_text: str | None = None  # STATUSTEXT after a scripted NACK
    stall_after: int | None = None  # after this many items of an upload: stop requesting
    disconnect_after: int | None = None  # after this many items of an upload: go silent
    # a faulty or hostile vehicle's downloads
    claim_count: int | None = None  # MISSION_COUNT says this many, whatever is stored
    item_fields: Mapping[int, Mapping] = field(default_factory=dict)  # seq -> fields replaced
    # a vehicle that stores something else than it received and acknowledged (ACCEPTED): the
    # items checked as received, then stored with these StoredItem fields replaced (item
    # number -> fields) and without these item numbers; downloads give what is stored
    store_fields: Mapping[int, Mapping] = field(default_factory=dict)
    store_drop: Collection[int] = ()
    # a parameter the vehicle keeps at this value whatever PARAM_SET asks (name -> value); it
    # answers every read with the value it keeps, and the set with it too unless
    # param_echo_set (then with the value asked for, as if it had taken it)
    param_keeps: Mapping[str, float] = field(default_factory=dict)
    param_echo_set: bool = False


@dataclass
class Upload:
    """The upload under way (ArduPilot's receiving state)."""

    count: int
    sysid: int
    compid: int
    items: list = field(default_factory=list)
    last_receive: float = 0.0
    last_request: float = 0.0
    stalled: bool = False

    @property
    def next_seq(self) -> int:
        return len(self.items)


class _Wire(MavlinkDatagrams):
    """The fake's socket: the kit's pymavlink-over-UDP endpoint, deaf while disconnected."""

    def __init__(self, vehicle: FakeVehicle):
        super().__init__(vehicle._mav, vehicle._received, vehicle._rejected)
        self.vehicle = vehicle

    def datagram_received(self, data, addr):
        if self.vehicle.disconnected:
            return
        self.vehicle._heard = True
        super().datagram_received(data, addr)


class FakeVehicle:
    """``async with FakeVehicle(fence=items, faults=Faults(...)) as fake:`` then connect MAVSDK
    to ``fake.url``. ``fake.fence`` is the stored fence (a list of StoredItem)."""

    def __init__(
        self,
        fence=(),
        faults: Faults | None = None,
        *,
        max_items: int = 70,
        storage_size: int = 560,
        upload_timeout: float = 8.0,
        rerequest_interval: float = 1.0,
        port: int | None = None,
        signing_key: bytes | None = None,
        params: Mapping[str, float] | None = None,
        armed: bool = False,
        reboot_seconds: float = 0.5,
        uptime: float = 60.0,
        mav_type: int = mav.MAV_TYPE_QUADROTOR,
        autopilot: int = mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
        home: tuple | None = None,
        firmware: tuple = (4, 7, 0),
    ):
        self.fence: list[StoredItem] = [StoredItem.of(it) for it in fence]
        self.params: dict[str, float] = dict(params or {})
        self.armed = armed
        self.mav_type = mav_type  # HEARTBEAT's type: a copter unless told
        self.autopilot = autopilot  # HEARTBEAT's autopilot: ArduPilot unless told
        self.custom_mode = 0  # HEARTBEAT's custom_mode (the autopilot's mode number)
        self.home = home  # (lon, lat): HOME_POSITION is answered only once home is set
        self.firmware = firmware  # AUTOPILOT_VERSION's flight_sw_version (major, minor, patch)
        self.reboot_seconds = reboot_seconds
        self.reboots = 0  # boots after the first
        self._boot_t0 = time.monotonic() - uptime  # SYSTEM_TIME's clock
        self.faults = faults or Faults()
        self.max_items = max_items
        self.storage_size = storage_size
        self.upload_timeout = upload_timeout
        self.rerequest_interval = rerequest_interval
        self.port = port or free_udp_port()
        self.log: list[tuple] = []  # (seconds since start, what, message name, detail)
        self.texts: list[str] = []  # STATUSTEXTs sent
        self.upload_results: list[int] = []  # MAV_MISSION_RESULT that ended each upload
        self.fence_writes = 0  # fences stored (successful uploads and clears)
        self.disconnected = False
        self.upload: Upload | None = None
        self._mav = mav.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self._wire = _Wire(self)  # parses and encodes with self._mav
        self.dropped = 0  # messages that did not decode, or were not signed with the key
        self.rejected: list[bytes] = []  # the bytes of each, as pymavlink cut them
        self.signing_setups: list[bytes] = []  # keys received in SETUP_SIGNING
        self._set_key(signing_key)
        # per direction: mission messages numbered so far, and the seeded random loss
        self._numbered = {"in": 0, "out": 0}
        self._rng = {
            "in": random.Random(self.faults.seed * 2 + 1),
            "out": random.Random(self.faults.seed * 2),
        }
        self._heard = False
        self._arrived = asyncio.Event()  # set whenever a message is logged as received
        self._t0 = time.monotonic()
        self._tasks: list[asyncio.Task] = []
        self._loop = None

    @property
    def url(self) -> str:
        return f"udpin://127.0.0.1:{self.port}"

    # ---------------------------------------------------------------- life cycle

    async def start(self):
        self._loop = asyncio.get_running_loop()
        self._t0 = time.monotonic()
        await self._wire.open(local_addr=("127.0.0.1", 0))
        self._tasks = [asyncio.create_task(self._heartbeats()), asyncio.create_task(self._update())]
        return self

    async def stop(self):
        await self._cancel_tasks()
        await self._wire.close()

    async def _cancel_tasks(self):
        """Cancel the heartbeat and update tasks and wait for them to end."""
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            try:
                await task
            except asyncio.CancelledError:
                pass
        self._tasks = []

    async def __aenter__(self):
        return await self.start()

    async def __aexit__(self, *exc):
        await self.stop()

    def disconnect(self):
        """Go silent: send nothing more (heartbeats included) and ignore what arrives."""
        self.disconnected = True
        self._note("disconnect", "", "")

    def reconnect(self):
        self.disconnected = False
        self._note("reconnect", "", "")

    def sent(self, name: str) -> list:
        """Details of the messages of that name that went out, late or not (not those lost)."""
        return [detail for _, what, n, detail in self.log if what.startswith("out") and n == name]

    def received(self, name: str) -> list:
        """Details of the messages of that name that came in (not those lost)."""
        return [detail for _, what, n, detail in self.log if what == "in" and n == name]

    async def wait_received(self, name: str, count: int = 1, timeout: float = 5.0) -> list:
        """:meth:`received` once ``count`` messages of that name have come in: for what a
        client sends about when its own call returns (MAVSDK's closing MISSION_ACK of a
        download comes over UDP, the download's result over gRPC: nothing orders the two).
        Raises TimeoutError after ``timeout`` seconds."""

        async def enough():
            while len(self.received(name)) < count:
                self._arrived.clear()
                await self._arrived.wait()

        await asyncio.wait_for(enough(), timeout)
        return self.received(name)

    # ---------------------------------------------------------------- wire

    def _now(self) -> float:
        return time.monotonic() - self._t0

    def _note(self, what, name, detail):
        self.log.append((round(self._now(), 4), what, name, detail))
        if what == "in":
            self._arrived.set()

    def _number(self, direction):
        """Number the next mission message going ``direction`` ("in" or "out"): (its number,
        whether the scripted faults lose it). The seeded generator is drawn from whenever
        random loss is on, dropped or not, so each seed gives one loss sequence."""
        n = self._numbered[direction]
        self._numbered[direction] += 1
        drop = self.faults.drop_in if direction == "in" else self.faults.drop_out
        loss = self.faults.loss_in if direction == "in" else self.faults.loss_out
        lost_at_random = bool(loss) and self._rng[direction].random() < loss
        return n, n in drop or lost_at_random

    def _send(self, msg, detail=""):
        """Encode and send one message, through the scripted faults."""
        if self._wire.transport is None or self.disconnected:
            return
        data = self._wire.encode(msg)  # a lost message still uses up a sequence number
        name = msg.get_type()
        delay = 0.0
        if name in MISSION_MESSAGES:
            n, lost = self._number("out")
            if lost:
                self._note("lost-out", name, detail)
                return
            delay = self.faults.delay_out.get(n, 0.0)
        if name != "HEARTBEAT":
            self._note("out" if not delay else f"out+{delay:g}s", name, detail)
        if delay:
            self._loop.call_later(delay, self._sendto, data)
        else:
            self._sendto(data)

    def _sendto(self, data):
        if not self.disconnected:
            self._wire.send(data, ("127.0.0.1", self.port))

    def _rejected(self, msg, addr):
        if msg is not None:  # garbled, or (signing on) not signed with the key
            self.dropped += 1
            self.rejected.append(bytes(msg.get_msgbuf()))

    def _received(self, msg, addr):
        if self.disconnected:  # a handler went silent: nothing more of this datagram
            return
        name = msg.get_type()
        target = getattr(msg, "target_system", None)
        if target not in (None, 0, SYSTEM_ID):
            return
        if name in MISSION_MESSAGES:
            _, lost = self._number("in")
            if lost:
                self._note("lost-in", name, _detail(msg))
                return
        if name not in ("HEARTBEAT",):
            self._note("in", name, _detail(msg))
        handler = getattr(self, "_on_" + name.lower(), None)
        if handler is not None:
            handler(msg)

    # ---------------------------------------------------------------- signing

    def _set_key(self, key: bytes | None, timestamp: int | None = None):
        """As ArduPilot's channel 1 (not the trusted USB channel 0): with a key, sign every
        message sent and drop every message not signed with it; an all-zero key: off."""
        signing = self._mav.signing
        if key is None or key == bytes(32):
            signing.secret_key, signing.sign_outgoing = None, False
            return
        signing.secret_key, signing.sign_outgoing = bytes(key), True
        signing.timestamp = timestamp or int((time.time() - 1420070400) * 100_000)
        signing.allow_unsigned_callback = None

    def _on_setup_signing(self, msg):
        key = bytes(msg.secret_key)
        self.signing_setups.append(key)
        self._set_key(key, msg.initial_timestamp)

    # ---------------------------------------------------------------- periodic

    async def _heartbeats(self):
        """1 Hz; every 0.1 s until the ground station is first heard, so that a test does not
        wait a second when MAVSDK starts listening just after the fake's first heartbeat."""
        while True:
            armed = mav.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
            self._send(
                mav.MAVLink_heartbeat_message(
                    self.mav_type,
                    self.autopilot,
                    mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
                    | armed,
                    self.custom_mode,
                    mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY,
                    3,
                )
            )
            await asyncio.sleep(1.0 if self._heard else 0.1)

    async def _update(self):
        """MissionItemProtocol::update: re-ask a stalled client, cancel after the timeout."""
        while True:
            await asyncio.sleep(0.02)
            up = self.upload
            if up is None:
                continue
            now = time.monotonic()
            if now - up.last_receive > self.upload_timeout:
                self.upload = None
                self.upload_results.append(mav.MAV_MISSION_OPERATION_CANCELLED)
                self._text("Fence upload timeout")  # timeout() comes before the ACK here
                self._ack(up.sysid, up.compid, mav.MAV_MISSION_OPERATION_CANCELLED)
                continue
            if not up.stalled and now - up.last_request > self.rerequest_interval:
                self._request(up)

    # ---------------------------------------------------------------- replies

    def _ack(self, sysid, compid, result, mission_type=FENCE):
        self._send(
            mav.MAVLink_mission_ack_message(sysid, compid, result, mission_type),
            _result_name(result),
        )

    def _text(self, text, severity=mav.MAV_SEVERITY_WARNING, delay=0.0):
        def send():
            self.texts.append(text)
            self._send(mav.MAVLink_statustext_message(severity, text.encode()[:50]), text)

        if delay and self._loop is not None:
            self._loop.call_later(delay, send)
        else:
            send()

    def _request(self, up: Upload, seq: int | None = None):
        seq = up.next_seq if seq is None else seq
        self._send(mav.MAVLink_mission_request_message(up.sysid, up.compid, seq, FENCE), seq)
        up.last_request = time.monotonic()

    def _request_next(self, up: Upload):
        """Request the next item, with the scripted request faults."""
        k = up.next_seq
        if k in self.faults.extra_requests:
            self._request(up, self.faults.extra_requests[k])
        self._request(up)
        if k in self.faults.duplicate_requests:
            self._request(up)

    def _end_upload(self, msg, result, text=None):
        self.upload = None
        self.upload_results.append(result)
        self._ack(msg.get_srcSystem(), msg.get_srcComponent(), result)
        if text:
            self._text(text, delay=TEXT_DELAY)

    # ---------------------------------------------------------------- handlers

    def _mavlink2(self, msg) -> bool:
        """mavlink2_requirement_met: fence transfers need MAVLink 2 (ArduPilot checks the
        protocol of its link, which follows the ground station's)."""
        if msg.get_msgbuf()[:1] == b"\xfd":
            return True
        self._text("Need mavlink2 for item transfer")
        self._ack(msg.get_srcSystem(), msg.get_srcComponent(), mav.MAV_MISSION_UNSUPPORTED)
        return False

    def _other_type(self, msg) -> bool:
        """This fake keeps a fence only; other mission types are refused."""
        if msg.mission_type == FENCE:
            return False
        self._ack(
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            mav.MAV_MISSION_UNSUPPORTED,
            msg.mission_type,
        )
        return True

    def _on_command_long(self, msg):
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        wants_version = (
            msg.command == mav.MAV_CMD_REQUEST_MESSAGE
            and int(msg.param1) == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION
        ) or msg.command == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
        if msg.target_component not in (0, COMPONENT_ID):
            return
        if msg.command == mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
            self._reboot(msg, src)
            return
        if (
            msg.command == mav.MAV_CMD_REQUEST_MESSAGE
            and int(msg.param1) == mav.MAVLINK_MSG_ID_HOME_POSITION
        ):  # GCS_MAVLINK::send_home_position: accepted, and nothing sent while home is unset
            self._send(mav.MAVLink_command_ack_message(msg.command, 0, 0, 0, *src))
            if self.home is not None:
                lon, lat = (round(v * 1e7) for v in self.home)
                self._send(mav.MAVLink_home_position_message(
                    lat, lon, 0, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0))  # fmt: skip
            return
        if (
            msg.command == mav.MAV_CMD_REQUEST_MESSAGE
            and int(msg.param1) == mav.MAVLINK_MSG_ID_SYSTEM_TIME
        ):
            self._send(mav.MAVLink_command_ack_message(msg.command, 0, 0, 0, *src))
            boot_ms = int((time.monotonic() - self._boot_t0) * 1000)
            self._send(mav.MAVLink_system_time_message(int(time.time() * 1e6), boot_ms), boot_ms)
            return
        result = mav.MAV_RESULT_ACCEPTED if wants_version else mav.MAV_RESULT_UNSUPPORTED
        self._send(mav.MAVLink_command_ack_message(msg.command, result, 0, 0, *src))
        if wants_version:
            self._send(
                mav.MAVLink_autopilot_version_message(
                    CAPABILITIES,
                    (self.firmware[0] << 24)
                    | (self.firmware[1] << 16)
                    | (self.firmware[2] << 8)
                    | 255,
                    0,
                    0,
                    0,
                    [0] * 8,
                    [0] * 8,
                    [0] * 8,
                    0,
                    0,
                    0x0123456789,
                )
            )

    # ---------------------------------------------------------------- parameters, reboot

    def _param_value(self, name, value=None):
        value = self.params[name] if value is None else value
        kind = mav.MAV_PARAM_TYPE_INT16 if isinstance(value, int) else mav.MAV_PARAM_TYPE_REAL32
        index = list(self.params).index(name)
        self._send(
            mav.MAVLink_param_value_message(
                name.encode(), float(value), kind, len(self.params), index
            ),
            (name, value),
        )

    def _on_param_request_read(self, msg):
        name = msg.param_id
        if not name and 0 <= msg.param_index < len(self.params):
            name = list(self.params)[msg.param_index]
        if name in self.params:  # ArduPilot does not answer for a name it does not have
            self._param_value(name)

    def _on_param_set(self, msg):
        name = msg.param_id
        if name not in self.params:
            return
        integer = isinstance(self.params[name], int)
        asked = int(round(msg.param_value)) if integer else msg.param_value
        kept = name in self.faults.param_keeps
        value = self.faults.param_keeps[name] if kept else asked
        self.params[name] = int(round(value)) if integer else value
        self._param_value(name, asked if kept and self.faults.param_echo_set else None)

    def _reboot(self, msg, src):
        """GCS_MAVLINK::handle_preflight_reboot, then AP_Vehicle::reboot: refused while armed;
        else acknowledged, silent 0.2 s later, and booted again after ``reboot_seconds``."""
        if self.armed:
            result = mav.MAV_RESULT_FAILED
        elif int(msg.param1) != 1:
            result = mav.MAV_RESULT_UNSUPPORTED
        else:
            result = mav.MAV_RESULT_ACCEPTED
        self._send(mav.MAVLink_command_ack_message(msg.command, result, 0, 0, *src), result)
        if result == mav.MAV_RESULT_ACCEPTED:
            self._loop.call_later(0.2, self._go_down)

    def _go_down(self):
        self._note("reboot", "", "")
        self.disconnected = True
        self.upload = None
        self._loop.call_later(self.reboot_seconds, self._boot)

    def _boot(self):
        kb = int(self.params.get("BRD_SD_FENCE", 0))
        if kb > 0:  # AC_PolyFence_loader::init attaches fence.stg: max_items = size / 8
            self.storage_size = min(kb * 1024, 0xFFFF)
            self.max_items = self.storage_size // 8
        self.reboots += 1
        self._boot_t0 = time.monotonic()
        self.disconnected = False
        self._note("boot", "", (self.max_items, self.storage_size))

    # ---------------------------------------------------------------- fence transfers

    def _on_mission_count(self, msg):
        if self._other_type(msg) or not self._mavlink2(msg):
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        up = self.upload
        if up is not None and (sysid, compid) != (up.sysid, up.compid):
            self._ack(sysid, compid, mav.MAV_MISSION_DENIED)
            return
        self.upload = None  # a repeated count from the same client restarts the upload
        if msg.count > self.max_items:
            self.upload_results.append(mav.MAV_MISSION_NO_SPACE)
            self._ack(sysid, compid, mav.MAV_MISSION_NO_SPACE)
            self._text(f"Only {self.max_items} items are supported", delay=TEXT_DELAY)
            return
        if self.faults.nack_count is not None:
            self._end_upload(msg, self.faults.nack_count, self.faults.nack_text)
            return
        if msg.count == 0:
            self._store([])
            self._end_upload(msg, mav.MAV_MISSION_ACCEPTED)
            return
        now = time.monotonic()
        up = self.upload = Upload(msg.count, sysid, compid, last_receive=now)
        if self._scripted_stop(up):
            return
        self._request_next(up)

    def _scripted_stop(self, up: Upload) -> bool:
        if self.faults.disconnect_after is not None and up.next_seq >= self.faults.disconnect_after:
            self.disconnect()
            return True
        if self.faults.stall_after is not None and up.next_seq >= self.faults.stall_after:
            if not up.stalled:
                up.stalled = True
                self._note("stall", "", up.next_seq)
            return True
        return False

    def _on_mission_item_int(self, msg):
        if self._other_type(msg) or not self._mavlink2(msg):
            return
        up = self.upload
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if up is None:
            self._ack(sysid, compid, mav.MAV_MISSION_ERROR)
            return
        if up.stalled:
            return  # a stalled vehicle does not listen either
        if msg.seq != up.next_seq:
            self._ack(sysid, compid, mav.MAV_MISSION_INVALID_SEQUENCE)
            return
        if (sysid, compid) != (up.sysid, up.compid):
            self._ack(sysid, compid, mav.MAV_MISSION_DENIED)
            return
        result = self._convert(msg)
        if self.faults.nack_item is not None and self.faults.nack_item[0] == msg.seq:
            result = self.faults.nack_item[1]
        if result != mav.MAV_MISSION_ACCEPTED:
            self._end_upload(msg, result, self.faults.nack_text if self.faults.nack_item else None)
            return
        up.items.append(StoredItem(msg.command, float(msg.param1), msg.x, msg.y))
        up.last_receive = time.monotonic()
        if up.next_seq >= up.count:
            self._complete(msg, up)
            return
        if self._scripted_stop(up):
            return
        self._request_next(up)

    def _convert(self, msg) -> int:
        """convert_MISSION_ITEM_INT_to_AC_PolyFenceItem."""
        if msg.frame not in GLOBAL_FRAMES:
            return mav.MAV_MISSION_UNSUPPORTED_FRAME
        if msg.command in POLYGONS:
            if msg.param1 > 255:
                return mav.MAV_MISSION_INVALID_PARAM1
        elif msg.command not in CIRCLES and msg.command != RETURN_POINT:
            return mav.MAV_MISSION_UNSUPPORTED
        return mav.MAV_MISSION_ACCEPTED

    def _complete(self, msg, up: Upload):
        """MissionItemProtocol_Fence::complete -> AC_PolyFence_loader::write_fence."""
        problem = validate(up.items)
        if problem is not None:
            self.upload = None
            self.upload_results.append(mav.MAV_MISSION_ERROR)
            self._ack(up.sysid, up.compid, mav.MAV_MISSION_ERROR)
            self._text(problem, delay=TEXT_DELAY)
            self._text("Fence validation failed", delay=TEXT_DELAY)
            return
        if storage_bytes(up.items) > self.storage_size:
            self._end_upload(msg, mav.MAV_MISSION_ERROR, "Fence exceeds storage size")
            return
        self._store(self._as_stored(up.items))
        self._end_upload(msg, mav.MAV_MISSION_ACCEPTED)
        self._text("Fence Indexed OK", mav.MAV_SEVERITY_DEBUG, delay=TEXT_DELAY)

    def _as_stored(self, items) -> list:
        """The received items as this vehicle stores them (``store_fields``, ``store_drop``)."""
        changed = self.faults.store_fields
        return [
            replace(it, **changed.get(seq, {}))
            for seq, it in enumerate(items)
            if seq not in self.faults.store_drop
        ]

    def _store(self, items):
        self.fence = list(items)
        self.fence_writes += 1

    def _may_download(self, msg) -> bool:
        """A fence download request this vehicle answers: MAVLink 2, fence type, and no
        upload under way (which ArduPilot answers with MISSION_ACK(DENIED))."""
        if self._other_type(msg) or not self._mavlink2(msg):
            return False
        if self.upload is not None:
            self._ack(msg.get_srcSystem(), msg.get_srcComponent(), mav.MAV_MISSION_DENIED)
            return False
        return True

    def _on_mission_request_list(self, msg):
        if not self._may_download(msg):
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        count = len(self.fence) if self.faults.claim_count is None else self.faults.claim_count
        self._send(mav.MAVLink_mission_count_message(sysid, compid, count, FENCE), count)

    def _on_mission_request_int(self, msg):
        if not self._may_download(msg):
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if msg.seq > len(self.fence):
            self._ack(sysid, compid, mav.MAV_MISSION_INVALID_SEQUENCE)
            return
        if msg.seq == len(self.fence):  # ArduPilot checks seq > count, then fails to read
            self._ack(sysid, compid, mav.MAV_MISSION_ERROR)
            return
        it = self.fence[msg.seq]
        param1 = float(int(it.param1)) if it.command in POLYGONS else it.param1
        item = mav.MAVLink_mission_item_int_message(
            sysid,
            compid,
            msg.seq,
            mav.MAV_FRAME_GLOBAL,
            RETURN_POINT if it.command == RETURN_POINT else it.command,
            0,
            0,
            0.0 if it.command == RETURN_POINT else param1,
            0.0,
            0.0,
            0.0,
            it.x,
            it.y,
            0.0,
            FENCE,
        )
        for name, value in self.faults.item_fields.get(msg.seq, {}).items():
            setattr(item, name, value)
        self._send(item, msg.seq)

    def _on_mission_clear_all(self, msg):
        if self._other_type(msg):
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if self.upload is not None:
            self._ack(sysid, compid, mav.MAV_MISSION_ERROR)
            return
        self._store([])
        self._ack(sysid, compid, mav.MAV_MISSION_ACCEPTED)


def _result_name(result) -> str:
    entry = mav.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name.replace("MAV_MISSION_", "") if entry else str(result)


def _detail(msg):
    name = msg.get_type()
    if name == "MISSION_ACK":
        return _result_name(msg.type)
    if name == "MISSION_COUNT":
        return msg.count
    if name == "COMMAND_LONG":
        return (msg.command, msg.param1)
    if name == "PARAM_SET":
        return (msg.param_id, msg.param_value)
    if name == "PARAM_REQUEST_READ":
        return msg.param_id
    return getattr(msg, "seq", "")
