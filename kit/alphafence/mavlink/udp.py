"""MAVLink over UDP on asyncio: pymavlink's codec on a datagram endpoint, written once.

The signed link's sockets (:mod:`alphafence.vehicle.bridge`), SITL's readiness listener
(:mod:`alphafence.sitl.readiness`) and the tests' scripted vehicle all talk MAVLink this way:
each datagram is parsed with a pymavlink ``MAVLink`` object in robust mode (a corrupt datagram
never raises), good messages go to one callback and rejected ones to another, the address of
the last datagram is remembered, and messages are sent packed by the same codec. No thread,
no blocking call. What a message *means* (signatures, readiness, a scripted fault) is the
caller's business.

The codec is passed in, so this module needs no pymavlink import of its own (pymavlink is the
optional ``vehicle`` extra).

Examples
--------
>>> from pymavlink.dialects.v20 import ardupilotmega
>>> got = []
>>> wire = MavlinkDatagrams(ardupilotmega.MAVLink(None), lambda msg, addr: got.append(msg))
>>> sender = ardupilotmega.MAVLink(None, srcSystem=1, srcComponent=1)
>>> wire.feed(sender.heartbeat_encode(2, 3, 0, 0, 4).pack(sender), ("127.0.0.1", 14550))
>>> [m.get_type() for m in got]
['HEARTBEAT']
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

BAD_DATA = "BAD_DATA"  # pymavlink's type name for a frame it could not accept
MARKER_V1, MARKER_V2 = 0xFE, 0xFD  # the first byte of a MAVLink 1 and a MAVLink 2 frame
HEADER_V1, HEADER_V2 = 6, 10  # header bytes, the marker included
CHECKSUM, SIGNATURE = 2, 13  # the bytes after the payload: CRC, and signature when flagged
SIGNED = 0x01  # MAVLINK_IFLAG_SIGNED: the frame carries a signature


def _ignore(msg, addr) -> None:
    return None


def _next_marker(buf, i: int, n: int) -> int:
    """The index of the next MAVLink marker in ``buf[i:n]`` (``n`` when there is none)."""
    v1, v2 = buf.find(MARKER_V1, i, n), buf.find(MARKER_V2, i, n)
    if v1 < 0:
        return n if v2 < 0 else v2
    return v1 if v2 < 0 else min(v1, v2)


class MavlinkDatagrams(asyncio.DatagramProtocol):
    """pymavlink's MAVLink codec on an asyncio datagram endpoint.

    Parameters
    ----------
    mav : pymavlink MAVLink object
        The codec: parses what arrives (its signing settings check signatures) and packs what
        :meth:`encode` and :meth:`send` are given. Robust parsing is switched on.
    on_message : callable
        ``on_message(msg, addr)`` for each message parsed (unknown message ids included: they
        are pymavlink ``MAVLink_unknown`` messages).
    on_bad : callable, optional
        ``on_bad(msg, addr)`` for each frame pymavlink rejected (``msg`` of type
        ``"BAD_DATA"``: a bad CRC, or a missing or wrong signature), and with ``msg=None``
        when the parser raised on a datagram (nothing of it is used).

    Attributes
    ----------
    peer : tuple or None
        The address the last datagram came from.
    wanted_ids : set of int or None
        When a set, only frames whose message id is in it are parsed (their CRC, signature and
        fields checked by pymavlink); the others are framed from their header and dropped
        unread, counted in ``skipped`` and given to ``on_skipped`` if it is set. None (the
        default): every frame is parsed. A frame that is dropped is never delivered, so it
        needs no checking: a listener that follows only a few message ids pays for those.
    skipped : int
        Frames dropped unread because their id was not wanted.
    on_skipped : callable or None
        ``on_skipped(frame)`` with the raw bytes of each frame dropped unread.
    fast : dict
        ``{message id: take}`` (with ``wanted_ids`` set): ``take(frame, addr) -> bool`` is
        given each whole MAVLink 2 frame of that id first, in order among the others; a frame
        it returns False for is parsed by pymavlink as any other (which rejects it or
        delivers it).
    transport : asyncio.DatagramTransport or None
        The endpoint while it is open.
    """

    def __init__(self, mav, on_message: Callable, on_bad: Callable | None = None):
        mav.robust_parsing = True
        self.mav = mav
        self.on_message = on_message
        self.on_bad = on_bad or _ignore
        self.peer: tuple | None = None
        self.wanted_ids: set[int] | None = None
        self.skipped = 0
        self.on_skipped: Callable | None = None
        self.fast: dict[int, Callable] = {}
        self._rest = b""  # an unfinished frame, when wanted_ids is set
        self.transport: asyncio.DatagramTransport | None = None
        self._connected = False  # opened with a remote address: sends go there only
        self._closed = asyncio.Event()

    # -- life cycle -----------------------------------------------------------------
    async def open(
        self, *, local_addr=None, remote_addr=None, allow_broadcast=False
    ) -> MavlinkDatagrams:
        """Open the endpoint: bound to ``local_addr``, or connected to ``remote_addr``
        (``allow_broadcast``: may send to a broadcast address).

        Raises OSError when the address cannot be bound or resolved.
        """
        self._closed.clear()
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(
            lambda: self,
            local_addr=local_addr,
            remote_addr=remote_addr,
            allow_broadcast=allow_broadcast or None,
        )
        return self

    async def close(self) -> None:
        """Close the endpoint and wait until its socket is closed (asyncio closes it on a
        later turn of the loop), so whoever binds the port next finds it free."""
        transport, self.transport = self.transport, None
        if transport is None:
            return
        transport.close()
        await self._closed.wait()

    @property
    def sockname(self) -> tuple | None:
        """The local address of the open endpoint (None when closed)."""
        return self.transport.get_extra_info("sockname") if self.transport else None

    def connection_made(self, transport) -> None:
        """asyncio: the endpoint is open."""
        self.transport = transport
        self._connected = transport.get_extra_info("peername") is not None

    def connection_lost(self, exc) -> None:
        """asyncio: the socket is closed."""
        self.transport = None
        self._closed.set()

    def error_received(self, exc) -> None:
        """asyncio: an ICMP error (port unreachable while the peer is not up yet): ignored."""

    # -- receiving ------------------------------------------------------------------
    def datagram_received(self, data: bytes, addr) -> None:
        """asyncio: remember ``addr`` as the peer, then :meth:`feed` the datagram."""
        self.peer = addr
        self.feed(data, addr)

    def feed(self, data: bytes, addr=None) -> None:
        """Parse ``data`` (a datagram, or a chunk of a stream) and deliver what it holds
        (the frames of :attr:`wanted_ids` only, when it is set)."""
        wanted = self.wanted_ids
        if wanted is None:
            self._parse(data, addr)
            return
        if self.fast and not self._rest and self._one_fast_frame(data, addr):
            return
        buf = self._rest + data if self._rest else data
        n, i, start = len(buf), 0, 0  # buf[start:i]: frames (and bytes) to parse
        while i < n:
            marker = buf[i]
            if marker == MARKER_V2:
                if n - i < HEADER_V2:
                    break
                size = HEADER_V2 + buf[i + 1] + CHECKSUM + (SIGNATURE if buf[i + 2] & SIGNED else 0)
                ident = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
            elif marker == MARKER_V1:
                if n - i < HEADER_V1:
                    break
                size = HEADER_V1 + buf[i + 1] + CHECKSUM
                ident = buf[i + 5]
            else:  # not MAVLink: up to the next marker, for pymavlink to reject
                i = _next_marker(buf, i + 1, n)
                continue
            if n - i < size:
                break
            if ident not in wanted:
                if start < i:
                    self._parse(buf[start:i], addr)
                self.skipped += 1
                if self.on_skipped is not None:
                    self.on_skipped(bytes(buf[i : i + size]))
                start = i + size
            elif marker == MARKER_V2 and (take := self.fast.get(ident)) is not None:
                if start < i:  # what came before it, first
                    self._parse(buf[start:i], addr)
                    start = i
                if take(bytes(buf[i : i + size]), addr):
                    start = i + size
            i += size
        if start < i:
            self._parse(buf if start == 0 and i == n else buf[start:i], addr)
        self._rest = bytes(buf[i:]) if i < n else b""

    def _one_fast_frame(self, data, addr) -> bool:
        """A datagram that is one whole MAVLink 2 frame of a :attr:`fast` id (a vehicle's
        telemetry at rate, as ArduPilot sends it): taken without the framing loop."""
        n = len(data)
        if n < HEADER_V2 or data[0] != MARKER_V2:
            return False
        if n != HEADER_V2 + data[1] + CHECKSUM + (SIGNATURE if data[2] & SIGNED else 0):
            return False
        take = self.fast.get(data[7] | data[8] << 8 | data[9] << 16)
        return take is not None and take(data, addr)

    def _parse(self, data, addr) -> None:
        """pymavlink parses ``data`` (whole frames, or any bytes when every id is wanted)."""
        try:
            messages = self.mav.parse_buffer(data) or []
        except Exception:  # robust parsing should not raise; a corrupt datagram never crashes
            self.on_bad(None, addr)
            return
        for msg in messages:
            if msg.get_type() == BAD_DATA:
                self.on_bad(msg, addr)
            else:
                self.on_message(msg, addr)

    # -- sending --------------------------------------------------------------------
    def encode(self, msg) -> bytes:
        """``msg`` packed by the codec (signed when it signs), its sequence number used up."""
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        return data

    def send(self, msg, addr=None) -> bool:
        """Send ``msg`` (bytes as they are, or a pymavlink message to :meth:`encode`) to
        ``addr``, else to the peer; a connected endpoint sends to its remote address.

        Returns
        -------
        bool
            False when there is nowhere to send (closed, or no peer heard yet); a message is
            then not encoded.
        """
        transport = self.transport
        if transport is None:
            return False
        if not self._connected:
            addr = addr if addr is not None else self.peer
            if addr is None:
                return False
        data = msg if isinstance(msg, bytes | bytearray | memoryview) else self.encode(msg)
        if self._connected:
            transport.sendto(data)
        else:
            transport.sendto(data, addr)
        return True
