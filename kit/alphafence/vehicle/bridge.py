"""A MAVLink link to the vehicle with message signing, and a loopback bridge that gives MAVSDK
a signed link.

MAVSDK's Python API cannot sign messages, so a signed connection runs through
:class:`SigningBridge`: MAVSDK talks unsigned MAVLink to the bridge on a loopback UDP port
(``udpout://127.0.0.1:PORT``), and the bridge talks to the vehicle over the operator's URL.
Each message from MAVSDK is decoded with pymavlink and packed again, signed with the key (its
source system, component and sequence number kept); each message from the vehicle is forwarded
as received only if its signature checks out with the key (and its timestamp moves forward,
pymavlink's replay rule). Unsigned and wrongly signed messages from the vehicle are dropped and
counted, so a failure can say which it was. RADIO_STATUS/RADIO, which a telemetry radio injects
unsigned, pass as ArduPilot lets them pass.

Everything runs on the asyncio loop (datagram endpoints for UDP, byte streams of
:mod:`alphafence.vehicle.transports` for serial ports and TCP): no blocking call. The link
takes every connection :func:`~alphafence.vehicle.endpoints.parse_endpoint` reads (serial
ports, ``udpin``, ``udpout``, ``udpbcast``, ``tcpout``, ``tcpin``), signed or not alike.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from alphafence.errors import VehicleError
from alphafence.mavlink.udp import MavlinkDatagrams
from alphafence.vehicle import fast_frames
from alphafence.vehicle.endpoints import Endpoint, parse_endpoint
from alphafence.vehicle.keys import signing_timestamp
from alphafence.vehicle.transports import TransportError, stream_transport

LOOPBACK = "127.0.0.1"
UDP_KINDS = ("udpin", "udpout", "udpbcast")
UNSIGNED_OK = frozenset({mavlink.MAVLINK_MSG_ID_RADIO_STATUS, mavlink.MAVLINK_MSG_ID_RADIO})
SIGNED_FLAG = mavlink.MAVLINK_IFLAG_SIGNED
MESSAGE_IDS = {  # name -> id (``msgname`` since pymavlink 2.4.31, ``name`` before)
    getattr(cls, "msgname", None) or cls.name: msgid for msgid, cls in mavlink.mavlink_map.items()
}


class BridgeError(VehicleError):
    """The vehicle side of a signed link could not be opened or went away."""


def is_signed(msgbuf: bytes) -> bool:
    """Whether a raw MAVLink frame carries a signature (MAVLink 2, incompat flag 1)."""
    return len(msgbuf) > 2 and msgbuf[0] == mavlink.PROTOCOL_MARKER_V2 and bool(msgbuf[2] & 1)


def signature_matches(msgbuf: bytes, key: bytes) -> bool:
    """Whether a signed frame was signed with ``key`` (the signature alone, no replay rule)."""
    import hashlib

    if not is_signed(msgbuf) or len(msgbuf) < 13 + 12:
        return False
    return hashlib.sha256(key + bytes(msgbuf[:-6])).digest()[:6] == bytes(msgbuf[-6:])


@dataclass
class LinkStats:
    """What a :class:`VehicleLink` accepted, sent and dropped."""

    received: int = 0  # messages accepted from the vehicle
    sent: int = 0  # messages sent to the vehicle
    unsigned: int = 0  # dropped: no signature (signing expected)
    bad_signature: int = 0  # dropped: signed with another key, or a replayed timestamp
    garbage: int = 0  # bytes that were not MAVLink, a bad CRC, or an unknown message id

    def diagnosis(self, key_given: bool) -> str:
        """Why the vehicle may have stayed silent, from what was dropped."""
        if not key_given:
            return ""
        if self.received == 0 and self.bad_signature:
            return (
                f"the vehicle's messages are signed with another key ({self.bad_signature} "
                "dropped): check the signing key"
            )
        if self.received == 0 and self.unsigned:
            return (
                f"the vehicle does not sign its messages ({self.unsigned} unsigned, dropped): "
                "install the key with `alphafence signing setup`, or connect without a signing key"
            )
        if self.received == 0:
            return "nothing at all came from the vehicle"
        return ""


class VehicleLink:
    """A raw MAVLink 2 link to the vehicle (pymavlink codec on asyncio transports).

    With ``key``, outgoing messages are signed and incoming ones must be (``verify=False``:
    signed, not checked); without it, nothing is signed and nothing is checked.
    ``on_message(msg)`` gets each accepted message. ``url`` is any connection
    :func:`~alphafence.vehicle.endpoints.parse_endpoint` reads (or an Endpoint); a malformed
    one raises its EndpointError here."""

    def __init__(
        self,
        url: str | Endpoint,
        key: bytes | None = None,
        on_message: Callable | None = None,
        *,
        verify: bool = True,
        link_id: int = 0,
        source: tuple[int, int] = (245, 190),  # a ground station, MAV_COMP_ID_MISSIONPLANNER
    ):
        self.endpoint = parse_endpoint(url)
        self.url = str(url).strip()
        self.kind = self.endpoint.kind
        self.key = key
        self.on_message = on_message or (lambda msg: None)
        self._recorder: Callable | None = None
        self.stats = LinkStats()
        # one codec reads (and checks signatures), one writes (and signs)
        self.reader = mavlink.MAVLink(None)
        self.mav = mavlink.MAVLink(None, srcSystem=source[0], srcComponent=source[1])
        if key is not None:
            self.mav.signing.secret_key = bytes(key)
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = link_id & 0xFF
            self.mav.signing.timestamp = signing_timestamp()
            if verify:
                self.reader.signing.secret_key = bytes(key)
                self.reader.signing.timestamp = self.mav.signing.timestamp
                self.reader.signing.allow_unsigned_callback = lambda _mav, msg_id: (
                    msg_id in UNSIGNED_OK
                )
                # the signature before the stream's timestamp moves (pymavlink moves it first)
                self.reader.check_signature = functools.partial(
                    fast_frames.check_signature, self.reader.signing
                )
        self.remote: tuple | None = None  # where the vehicle is (UDP)
        self._closed: str | None = None  # why the link ended
        # the socket (UDP), and the parser of a stream (serial, TCP) too
        self._wire = MavlinkDatagrams(self.reader, self._accept, self._reject)
        self._stream = None
        if self.kind not in UDP_KINDS:
            self._stream = stream_transport(self.endpoint, lambda data: self._received(data, None))

    @property
    def wanted_ids(self) -> set[int] | None:
        """The message ids parsed and delivered; the other frames are dropped unread
        (:attr:`~alphafence.mavlink.udp.MavlinkDatagrams.wanted_ids`). None (the default):
        every message. The link reads the set it is given as it changes."""
        return self._wire.wanted_ids

    @wanted_ids.setter
    def wanted_ids(self, ids: set[int] | None) -> None:
        self._wire.wanted_ids = ids

    @property
    def skipped(self) -> int:
        """Frames dropped unread: their message id was not :attr:`wanted`."""
        return self._wire.skipped

    @property
    def recorder(self) -> Callable | None:
        """``recorder(frame)`` gets the bytes of each accepted frame, and of each frame
        dropped unread when the link is not signed (a log of the whole link, as it came; with
        a key only what was verified is recorded)."""
        return self._recorder

    @recorder.setter
    def recorder(self, recorder: Callable | None) -> None:
        self._recorder = recorder
        self._wire.on_skipped = recorder if self.key is None else None

    @property
    def closed(self) -> str | None:
        """Why the link ended (None while it lives)."""
        return self._closed or (self._stream.closed if self._stream is not None else None)

    @closed.setter
    def closed(self, why: str | None) -> None:
        self._closed = why

    # -- life cycle -----------------------------------------------------------------
    async def open(self) -> VehicleLink:
        """Open the connection. Raises BridgeError (one line) when it cannot."""
        ep = self.endpoint
        try:
            if self._stream is not None:
                await self._stream.open()
            elif ep.kind == "udpin":
                await self._wire.open(local_addr=ep.address)
            elif ep.kind == "udpout":
                self.remote = ep.address
                await self._wire.open(remote_addr=self.remote)
            else:  # udpbcast: to the broadcast address until the vehicle answers
                self.remote = ep.address
                await self._wire.open(local_addr=("0.0.0.0", 0), allow_broadcast=True)
        except TransportError as exc:
            raise BridgeError(str(exc)) from None
        except OSError as exc:
            raise BridgeError(f"{self.url}: cannot open the connection ({exc})") from None
        return self

    async def close(self) -> None:
        """Close the connection (and wait until its socket or port is closed)."""
        if self._stream is not None:
            await self._stream.close()
        await self._wire.close()

    async def __aenter__(self):
        return await self.open()

    async def __aexit__(self, *exc):
        await self.close()

    # -- sending --------------------------------------------------------------------
    def send(self, msg, source: tuple[int, int] | None = None, seq: int | None = None) -> None:
        """Pack ``msg`` (a pymavlink message, new or decoded), signed when there is a key, and
        send it. ``source``/``seq`` keep the original sender's ids when forwarding."""
        mav = self.mav
        own = mav.srcSystem, mav.srcComponent
        if source is not None:
            mav.srcSystem, mav.srcComponent = source
        if seq is not None:
            mav.seq = seq
        try:
            buf = msg.pack(mav)
        finally:
            mav.srcSystem, mav.srcComponent = own
        mav.seq = (mav.seq + 1) % 256
        self._write(buf)

    def _write(self, buf: bytes) -> None:
        if self._stream is not None:
            if not self._stream.write(buf):
                return  # tcpin before the vehicle connected, or a port gone
        elif self.remote is None or not self._wire.send(buf, self.remote):
            return  # udpin before the vehicle has been heard: nowhere to send yet
        self.stats.sent += 1

    # -- receiving ------------------------------------------------------------------
    @contextlib.contextmanager
    def fast(self, cls, deliver: Callable, alone: Callable[[], bool] = lambda: True):
        """``with link.fast(cls, deliver):`` the messages of pymavlink class ``cls`` are
        decoded straight from their frames (:mod:`alphafence.vehicle.fast_frames`) and given
        to ``deliver(fields, system, component)`` (the fields in wire order) instead of
        ``on_message``, while ``alone()`` says nothing else follows them; the frames it cannot
        vouch for go to pymavlink as before."""
        from alphafence.vehicle.fast_frames import FrameDecoder

        decoder = FrameDecoder(cls)
        reader = self.reader

        def take(frame, addr) -> bool:
            if not alone():
                return False
            signing = reader.signing if reader.signing.secret_key is not None else None
            fields = decoder.decode(frame, signing)
            if fields is None:
                return False
            if self.key is not None:
                self._follow_timestamp(frame)
            self._accepted(frame, addr)
            deliver(fields, frame[5], frame[6])
            return True

        self._wire.fast[decoder.msgid] = take
        try:
            yield decoder
        finally:
            self._wire.fast.pop(decoder.msgid, None)

    def _received(self, data: bytes, addr) -> None:
        """Bytes from the vehicle (a datagram, or a chunk of a serial or TCP stream)."""
        self._wire.feed(data, addr)

    def _accept(self, msg, addr) -> None:
        if isinstance(msg, mavlink.MAVLink_unknown):
            # an id this dialect does not know: pymavlink returns it without checking
            # the signature, so it is dropped, never forwarded
            self.stats.garbage += 1
            return
        if self.key is not None:
            self._follow_timestamp(msg.get_msgbuf())
        self._accepted(msg.get_msgbuf(), addr)
        self.on_message(msg)

    def _accepted(self, frame, addr) -> None:
        if self.kind in ("udpin", "udpbcast") and addr is not None:
            self.remote = addr  # learnt from accepted (verified, when signing) messages only
        self.stats.received += 1
        if self._recorder is not None:
            self._recorder(frame)

    def _reject(self, msg, addr) -> None:
        if msg is None:  # the parser raised (robust parsing should not); never crash
            self.stats.garbage += 1
        else:
            self._count_bad(msg)

    def _follow_timestamp(self, buf) -> None:
        """Sign with timestamps no older than the vehicle's (those of the frame ``buf``): it
        rejects a new stream more than a minute behind its own clock (which runs ahead of ours
        in SITL at a speedup)."""
        if is_signed(buf) and len(buf) >= 25:
            ts = int.from_bytes(bytes(buf[-12:-6]), "little")
            if ts > self.mav.signing.timestamp:
                self.mav.signing.timestamp = ts

    def _count_bad(self, msg) -> None:
        if "signature" in str(getattr(msg, "reason", "")):
            if is_signed(bytes(msg.data)):
                self.stats.bad_signature += 1
            else:
                self.stats.unsigned += 1
        else:
            self.stats.garbage += 1


class SigningBridge:
    """``async with SigningBridge(url, key) as bridge:`` then point MAVSDK at
    ``bridge.local_url``. ``bridge.link.stats`` counts what was accepted and dropped.

    ``url`` is any connection :class:`VehicleLink` takes (a serial port included); with
    ``key=None`` the bridge only carries messages (for a connection MAVSDK cannot open)."""

    def __init__(self, url: str | Endpoint, key: bytes | None, *, link_id: int = 0):
        self.key = key
        self.link = VehicleLink(url, key, self._from_vehicle, link_id=link_id)
        self.local = mavlink.MAVLink(None)
        # MAVSDK's side; its peer is MAVSDK's address, learnt from its first datagram
        self._local = MavlinkDatagrams(self.local, self._from_mavsdk, self._not_forwarded)
        self._local_port: int | None = None
        self.from_mavsdk = 0
        self.not_forwarded = 0  # messages MAVSDK sent that pymavlink's dialect does not know

    @property
    def local_url(self) -> str:
        """Where MAVSDK connects: ``udpout://127.0.0.1:PORT``."""
        if self._local_port is None:
            raise BridgeError("the signing bridge is not open")
        return f"udpout://{LOOPBACK}:{self._local_port}"

    async def open(self) -> SigningBridge:
        """Open the link to the vehicle, then MAVSDK's loopback port. Raises BridgeError
        when the vehicle side cannot be opened."""
        await self.link.open()
        try:
            await self._local.open(local_addr=(LOOPBACK, 0))
        except OSError:
            await self.link.close()
            raise
        self._local_port = self._local.sockname[1]
        return self

    async def close(self) -> None:
        """Close MAVSDK's port and the link to the vehicle."""
        await self._local.close()
        await self.link.close()

    async def __aenter__(self):
        return await self.open()

    async def __aexit__(self, *exc):
        await self.close()

    def diagnosis(self) -> str:
        """Why the vehicle may have stayed silent ('' when nothing points to a reason)."""
        return self.link.closed or self.link.stats.diagnosis(key_given=self.key is not None)

    def _from_vehicle(self, msg) -> None:
        self._local.send(bytes(msg.get_msgbuf()))  # to MAVSDK, once it has been heard

    def _from_mavsdk(self, msg, addr) -> None:
        if isinstance(msg, mavlink.MAVLink_unknown):
            self.not_forwarded += 1
            return
        self.from_mavsdk += 1
        self.link.send(msg, (msg.get_srcSystem(), msg.get_srcComponent()), msg.get_seq())

    def _not_forwarded(self, msg, addr) -> None:
        if msg is not None:  # a frame pymavlink rejected (a datagram it raised on: nothing)
            self.not_forwarded += 1
