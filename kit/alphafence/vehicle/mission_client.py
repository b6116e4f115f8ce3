"""The MAVLink mission protocol, client side, on asyncio: upload and download of one mission
type (the fence, or the mission), with the retries a lossy link needs.

As ArduPilot's MissionItemProtocol serves it: an upload is MISSION_COUNT, then one
MISSION_ITEM_INT for each MISSION_REQUEST(_INT) the vehicle sends, until its MISSION_ACK; a
download is MISSION_REQUEST_LIST -> MISSION_COUNT, then MISSION_REQUEST_INT -> MISSION_ITEM_INT
for each item, and our MISSION_ACK. A message that gets no answer within :data:`RETRY_S` is sent
again, up to :data:`RETRIES` times; a refusal (a MISSION_ACK with an error) ends the transfer at
once, except INVALID_SEQUENCE during an upload: ArduPilot answers so an item it already has (our
re-send crossed its next request) and goes on. Failures raise :class:`~alphafence.vehicle.values.TransferFailed` with MAVSDK's result
names, so the caller words them once whichever link carried the transfer.
"""

from __future__ import annotations

import asyncio
import math
import time

from alphafence.mavlink import ids
from alphafence.vehicle.values import RawItem, TransferFailed, mission_result_name

RETRY_S = 0.75  # no answer within this: send the last message again
RETRIES = 4  # ... this many times, then TIMEOUT (about 3 s of silence, as MAVSDK)
REQUESTS = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
ANSWERS = ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ACK")


class MissionClient:
    """Transfers with one vehicle over a pymavlink link.

    Parameters
    ----------
    vehicle : PymavlinkVehicle
        Gives ``link`` (``send``, ``mav``: the codec), ``bus`` (``subscribe``) and
        ``target`` (the autopilot's system and component ids).

    Attributes
    ----------
    counts : dict
        ``MAV_MISSION_TYPE`` -> the number of items of its last completed transfer.
    """

    def __init__(self, vehicle):
        self.vehicle = vehicle
        self._lock = asyncio.Lock()  # one transfer at a time, as the protocol has it
        self.counts: dict[int, int] = {}  # mission type -> items of its last transfer

    def _mav(self):
        return self.vehicle.link.mav

    def _from_target(self, msg, mission_type) -> bool:
        sysid, compid = self.vehicle.target
        return (
            msg.get_srcSystem() == sysid
            and msg.get_srcComponent() == compid
            and getattr(msg, "mission_type", ids.MAV_MISSION_TYPE_MISSION) == mission_type
        )

    async def _next(self, queue, mission_type, resend, state):
        """The next message of this transfer from the vehicle; ``resend()`` after each
        :data:`RETRY_S` of silence, TIMEOUT after :data:`RETRIES`."""
        while True:
            try:
                msg = await asyncio.wait_for(queue.get(), RETRY_S)
            except asyncio.TimeoutError:
                if time.monotonic() - state.get("moved", -math.inf) < RETRY_S:
                    state["tries"] = 0  # it went on meanwhile (answered as it came)
                    continue
                state["tries"] += 1
                if state["tries"] > RETRIES:
                    raise TransferFailed("TIMEOUT") from None
                resend()
                continue
            if self._from_target(msg, mission_type):
                return msg

    async def upload(self, items, mission_type: int) -> float:
        """Send ``items`` (FenceItem-like: ``command``, ``param1``, ``lat``, ``lon``; or
        :class:`RawItem`) as the vehicle's ``mission_type``; returns the seconds it took.

        Raises
        ------
        TransferFailed
            The vehicle refused (its MISSION_ACK's result), or stopped answering (TIMEOUT).
        """
        async with self._lock:
            return await self._upload(
                [self._item_msg(i, it, mission_type) for i, it in enumerate(items)], mission_type
            )

    async def _upload(self, messages, mission_type) -> float:
        sysid, compid = self.vehicle.target
        mav, link = self._mav(), self.vehicle.link
        n = len(messages)
        t0 = time.monotonic()
        state = {"tries": 0, "last": mav.mission_count_encode(sysid, compid, n, mission_type)}
        state["sent_last"] = n == 0

        def request(msg) -> bool:
            """Answer a request for an item as it is parsed (no wake-up between them)."""
            if msg.get_type() == "MISSION_ACK" or not self._from_target(msg, mission_type):
                return False
            seq = int(msg.seq)
            if 0 <= seq < n:  # a request for an item we do not have: the ACK will say
                if seq > state.get("highest", -1):  # a new item asked for: it goes on
                    state["highest"], state["moved"] = seq, time.monotonic()
                state["last"] = messages[seq]
                state["sent_last"] = state["sent_last"] or seq == n - 1
                link.send(messages[seq])
            return True

        with self.vehicle.bus.subscribe(*REQUESTS, handle=request) as queue:
            link.send(state["last"])
            while True:
                msg = await self._next(queue, mission_type, lambda: link.send(state["last"]), state)
                if msg.type == ids.MAV_MISSION_ACCEPTED and state["sent_last"]:
                    self.counts[mission_type] = n
                    return time.monotonic() - t0
                if msg.type == ids.MAV_MISSION_INVALID_SEQUENCE:
                    continue  # an item it had already (a re-send): ArduPilot goes on
                if msg.type == ids.MAV_MISSION_ACCEPTED:  # an ACK before the last item
                    raise TransferFailed("PROTOCOL_ERROR", "accepted before the last item")
                raise TransferFailed(mission_result_name(msg.type))

    def _item_msg(self, seq, it, mission_type):
        from alphafence.geo.coords import to_e7

        sysid, compid = self.vehicle.target
        if isinstance(it, RawItem):
            fields = (
                it.frame,
                it.command,
                it.current,
                it.autocontinue,
                it.param1,
                it.param2,
                it.param3,
                it.param4,
                it.x,
                it.y,
                it.z,
            )
        else:  # a FenceItem: frame GLOBAL, positions in 1e-7 degrees
            fields = (
                ids.MAV_FRAME_GLOBAL,
                it.command,
                0,
                1,
                float(it.param1),
                0.0,
                0.0,
                0.0,
                to_e7(it.lat),
                to_e7(it.lon),
                0.0,
            )
        return self._mav().mission_item_int_encode(sysid, compid, seq, *fields, mission_type)

    async def download(self, mission_type: int, max_items: int | None = None) -> list:
        """The vehicle's items of ``mission_type`` as :class:`RawItem` ([] when it has none).

        Parameters
        ----------
        mission_type : int
            ``MAV_MISSION_TYPE``.
        max_items : int, optional
            A count above this is refused before any item is asked for
            (TransferFailed ``COUNT_TOO_LARGE``, its detail the count).
        """
        async with self._lock:
            return await self._download(mission_type, max_items)

    async def _download(self, mission_type, max_items):
        sysid, compid = self.vehicle.target
        mav, link = self._mav(), self.vehicle.link
        state = {"tries": 0, "last": mav.mission_request_list_encode(sysid, compid, mission_type)}
        taken: list = []  # the items, in order, as they arrive

        def item(msg) -> bool:
            """Take the item asked for and ask for the next one at once; the last item goes
            to the queue (it ends the wait), as do the COUNT and any ACK."""
            if msg.get_type() != "MISSION_ITEM_INT" or not self._from_target(msg, mission_type):
                return False
            n = state.get("n")
            if n is None or int(msg.seq) != len(taken):
                return True  # before the count, or one asked for before: ignored
            if len(taken) == n - 1:
                return False
            taken.append(_raw(msg))
            state["moved"] = time.monotonic()
            state["last"] = mav.mission_request_int_encode(sysid, compid, len(taken), mission_type)
            link.send(state["last"])
            return True

        with self.vehicle.bus.subscribe(*ANSWERS, handle=item) as queue:
            link.send(state["last"])
            while True:
                msg = await self._next(queue, mission_type, lambda: link.send(state["last"]), state)
                if msg.get_type() == "MISSION_ACK":
                    _refused(msg)
                    continue
                if msg.get_type() == "MISSION_COUNT":
                    break
            n = int(msg.count)
            if max_items is not None and n > max_items:
                raise TransferFailed("COUNT_TOO_LARGE", str(n))
            items = taken
            if n:
                state["n"] = n
                state["last"] = mav.mission_request_int_encode(sysid, compid, 0, mission_type)
                state["tries"] = 0
                link.send(state["last"])
            while len(items) < n:
                msg = await self._next(queue, mission_type, lambda: link.send(state["last"]), state)
                if msg.get_type() == "MISSION_ACK":
                    _refused(msg)
                    continue
                if msg.get_type() == "MISSION_ITEM_INT" and int(msg.seq) == len(items):
                    items.append(_raw(msg))  # the last one: the others were taken as they came
            link.send(mav.mission_ack_encode(sysid, compid, ids.MAV_MISSION_ACCEPTED, mission_type))
            self.counts[mission_type] = n
            return items


DOWNLOAD_REFUSALS = (ids.MAV_MISSION_DENIED, ids.MAV_MISSION_UNSUPPORTED)
"""The MISSION_ACKs that refuse a download (ArduPilot: DENIED while an upload is under way).
Any other ACK during a download is a late answer to an earlier transfer (the ERROR a vehicle
sends for a repeated last item, after it has stored the fence) and is ignored: the download's
own retries and timeout still bound it."""


def _refused(msg) -> None:
    """Raise TransferFailed if ``msg`` (a MISSION_ACK during a download) refuses it."""
    if msg.type in DOWNLOAD_REFUSALS:
        raise TransferFailed(mission_result_name(msg.type))


def _raw(msg) -> RawItem:
    return RawItem(
        int(msg.seq),
        int(msg.frame),
        int(msg.command),
        int(msg.current),
        int(msg.autocontinue),
        float(msg.param1),
        float(msg.param2),
        float(msg.param3),
        float(msg.param4),
        int(msg.x),
        int(msg.y),
        float(msg.z),
        int(msg.mission_type),
    )
