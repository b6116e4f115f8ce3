"""Fence upload and download against a scripted ArduPilot peer (tests/fake_vehicle.py) that
loses, repeats, re-orders and refuses messages, stalls and goes away, on each vehicle link
(the ``link`` fixture: every test here runs on both).

The pymavlink link (alphafence.vehicle.mission_client) re-sends its last message after 0.75 s of
silence, up to 4 times, and takes MISSION_ACK(INVALID_SEQUENCE) in an upload as ArduPilot means
it (an item it already had; the transfer goes on): it survives every loss below, and the
repeated and stale requests that end MAVSDK's upload.

What MAVSDK 4.1 (mission_transfer_client.cpp) does with each fault shapes what can succeed:

* Its upload waits 0.5 s per retry, 5 retries, and counts its own re-sent items as retries;
  ArduPilot re-asks for a missing item every second. So one lost message in a step costs about
  a second and the upload goes on, a request lost twice still arrives in time (the third ask
  comes at 2 s, MAVSDK gives up at 2.5 s), but a lost item plus one more loss in the same
  exchange (the item again, or the vehicle's re-ask) races MAVSDK's limit, and three losses
  end the upload (TIMEOUT). At 5 % random loss each way a 30-item upload fails about one time
  in four; the kit then fails cleanly, saying the vehicle kept its old fence.
* Any MISSION_ACK ends its upload. When the vehicle asks for an item a second time (a repeated
  or stale request), MAVSDK sends that item again; ArduPilot answers an item it is not
  expecting with MISSION_ACK(INVALID_SEQUENCE) and MAVSDK stops there. So repeated or stale
  requests do NOT recover: the kit must fail cleanly, and the vehicle keeps its old fence (it
  cancels the half-done upload itself 8 s after the last item, "Fence upload timeout"). A
  request for an item ahead of the expected one is ignored by MAVSDK, harmlessly.
* Its download ignores MISSION_ACK (DENIED while the vehicle is mid-upload): it times out, so
  the kit keeps asking until the vehicle has cancelled the abandoned upload.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)
from alphafence.vehicle.fence_transfer import (
    FenceTransferError,
    download_fence,
    same_items,
    upload_fence,
)
from alphafence.vehicle.link import LinkError, open_vehicle
from tests.fake_vehicle import FakeVehicle, Faults, free_udp_port

pytestmark = pytest.mark.usefixtures("link")


def polygon(n, command=POLYGON_EXCLUSION, lon0=14.49, lat0=35.86, r=0.003, param1=None):
    return [
        FenceItem(
            command,
            float(n if param1 is None else param1),
            round(lon0 + r * math.cos(2 * math.pi * i / n), 7),
            round(lat0 + r * math.sin(2 * math.pi * i / n), 7),
        )
        for i in range(n)
    ]


PREVIOUS = polygon(5, POLYGON_INCLUSION, r=0.01)  # on the vehicle before each upload
NEW = polygon(8) + [
    FenceItem(CIRCLE_EXCLUSION, 75.5, 14.4812345, 35.8712345),
    FenceItem(RETURN_POINT, 0.0, 14.4954321, 35.8554321),
]


def held(fake) -> list[FenceItem]:
    """The fake's stored fence as kit items."""
    return [FenceItem(it.command, it.param1, it.lon, it.lat) for it in fake.fence]


def lost(fake) -> list[tuple]:
    return [(what, name, detail) for _, what, name, detail in fake.log if what.startswith("lost")]


async def upload_to(fake, items, deadline=60.0):
    """Upload through open_vehicle; (report or None, error or None). ``deadline`` only stops a
    hang (asyncio.TimeoutError fails the test): what each test waits for is in the fake's log."""
    async with open_vehicle(fake.url, timeout=5.0) as vehicle:
        try:
            return await asyncio.wait_for(upload_fence(vehicle, items), deadline), None
        except FenceTransferError as exc:
            return None, exc


def repaired(fake) -> list[tuple]:
    """Every mission message the fake lost, each checked to have come again later (re-sent by
    the client or the vehicle, or answered anew): the losses that were NOT repaired. A lost
    MISSION_ACK is never sent again (the read-back tells instead), so it is left out."""
    return [
        (what, name, detail)
        for what, name, detail in lost(fake)
        if name != "MISSION_ACK"
        and detail not in (fake.received(name) if what == "lost-in" else fake.sent(name))
    ]


def one_upload_accepted(fake) -> bool:
    """The upload went through in one transfer the vehicle accepted: it never gave up on it
    (no "Fence upload timeout", no OPERATION_CANCELLED) and never had to refuse a read-back
    while the upload was under way (MISSION_ACK DENIED)."""
    return (
        fake.upload_results == [mav.MAV_MISSION_ACCEPTED]
        and fake.fence_writes == 1
        and "Fence upload timeout" not in fake.texts
        and "DENIED" not in fake.sent("MISSION_ACK")
    )


def read_back_once_cancelled(fake) -> bool:
    """The kit kept asking for the fence until the vehicle had cancelled the abandoned upload
    (ArduPilot's "Fence upload timeout", then MISSION_ACK OPERATION_CANCELLED), and its first
    download answered (MISSION_COUNT) came after that: every download asked for before it was
    refused (DENIED), ignored (a vehicle busy with an upload, or one that stopped listening) or
    lost."""
    log = [(what, name, detail) for _, what, name, detail in fake.log]
    out = [k for k, (what, _, _) in enumerate(log) if what.startswith("out")]
    cancel = next(k for k in out if log[k][1:] == ("MISSION_ACK", "OPERATION_CANCELLED"))
    counts = [k for k in out if log[k][1] == "MISSION_COUNT"]
    asked_before = [
        k for k, (_, name, _) in enumerate(log[:cancel]) if name == "MISSION_REQUEST_LIST"
    ]
    return bool(counts) and counts[0] > cancel and bool(asked_before)


def assert_upload_kept_old_fence(
    fake, err, *, says=(), holds="still holds its previous fence (5 items)"
):
    msg = str(err)
    assert "\n" not in msg and "\r" not in msg, msg
    assert msg.startswith(f"upload of {len(NEW)} fence items failed: "), msg
    for text in says:
        assert text in msg, msg
    assert holds in msg, msg
    assert same_items(PREVIOUS, held(fake)) == []
    assert fake.fence_writes == 0


# ------------------------------------------------------------------ the fake itself


class RawClient(asyncio.DatagramProtocol):
    """A bare pymavlink ground station, to check the fake's side of the protocol directly."""

    def __init__(self, mavlink1=False):
        self.mav = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self.mavlink1 = mavlink1
        self.queue: asyncio.Queue = asyncio.Queue()
        self.transport = None
        self.peer = None
        self.heard = asyncio.Event()  # the first datagram: it says where the fake is

    def connection_made(self, transport):
        self.transport = transport

    def datagram_received(self, data, addr):
        self.peer = addr
        self.heard.set()
        for msg in self.mav.parse_buffer(data) or []:
            if msg.get_type() not in ("HEARTBEAT", "BAD_DATA"):
                self.queue.put_nowait(msg)

    def send(self, msg):
        self.transport.sendto(msg.pack(self.mav, force_mavlink1=self.mavlink1), self.peer)

    async def expect(self, name, timeout=10.0):
        """The next message of that name (those of other names before it are skipped);
        asyncio.TimeoutError when none comes within ``timeout`` seconds."""

        async def next_of_name():
            while (msg := await self.queue.get()).get_type() != name:
                pass
            return msg

        return await asyncio.wait_for(next_of_name(), timeout)


async def raw_client(fake, mavlink1=False) -> RawClient:
    loop = asyncio.get_running_loop()
    _, client = await loop.create_datagram_endpoint(
        lambda: RawClient(mavlink1), local_addr=("127.0.0.1", fake.port)
    )
    try:  # until the first heartbeat says where the fake is
        await asyncio.wait_for(client.heard.wait(), 10.0)
    except asyncio.TimeoutError:
        client.transport.close()
        raise AssertionError("no heartbeat from the fake") from None
    return client


async def test_fake_speaks_ardupilot_fence_protocol():
    async with FakeVehicle(fence=PREVIOUS) as fake:
        client = await raw_client(fake)
        try:
            client.send(mav.MAVLink_mission_count_message(1, 1, 3, mav.MAV_MISSION_TYPE_FENCE))
            for seq, it in enumerate(polygon(3)):
                req = await client.expect("MISSION_REQUEST")  # id 40, as ArduPilot asks
                assert req.seq == seq and req.mission_type == mav.MAV_MISSION_TYPE_FENCE
                client.send(
                    mav.MAVLink_mission_item_int_message(
                        1,
                        1,
                        seq,
                        0,
                        it.command,
                        0,
                        1,
                        it.param1,
                        0,
                        0,
                        0,
                        round(it.lat * 1e7),
                        round(it.lon * 1e7),
                        0,
                        mav.MAV_MISSION_TYPE_FENCE,
                    )
                )
            ack = await client.expect("MISSION_ACK")
            assert ack.type == mav.MAV_MISSION_ACCEPTED
            assert same_items(polygon(3), held(fake)) == []
            client.send(mav.MAVLink_mission_request_list_message(1, 1, mav.MAV_MISSION_TYPE_FENCE))
            assert (await client.expect("MISSION_COUNT")).count == 3
            client.send(
                mav.MAVLink_mission_request_int_message(1, 1, 2, mav.MAV_MISSION_TYPE_FENCE)
            )
            item = await client.expect("MISSION_ITEM_INT")
            assert (item.seq, item.frame, item.x) == (2, 0, round(polygon(3)[2].lat * 1e7))
        finally:
            client.transport.close()


async def test_fake_needs_mavlink2():
    async with FakeVehicle(fence=PREVIOUS) as fake:
        client = await raw_client(fake, mavlink1=True)
        try:
            client.send(mav.MAVLink_mission_count_message(1, 1, 3, mav.MAV_MISSION_TYPE_FENCE))
            text = await client.expect("STATUSTEXT")  # ArduPilot's text comes before its ACK
            assert text.text == "Need mavlink2 for item transfer"
            assert (await client.expect("MISSION_ACK")).type == mav.MAV_MISSION_UNSUPPORTED
            assert same_items(PREVIOUS, held(fake)) == [] and fake.upload is None
        finally:
            client.transport.close()


# ------------------------------------------------------------------ download


async def test_download_empty_fence():
    async with FakeVehicle() as fake, open_vehicle(fake.url, timeout=5.0) as vehicle:
        assert await asyncio.wait_for(download_fence(vehicle), 5.0) == []


async def test_download_fence():
    async with FakeVehicle(fence=NEW) as fake, open_vehicle(fake.url, timeout=5.0) as vehicle:
        got = await asyncio.wait_for(download_fence(vehicle), 5.0)
        assert same_items(NEW, got) == []
        # MAVSDK closes the download with an ACK, which may come after its result: wait
        assert await fake.wait_received("MISSION_ACK") == ["ACCEPTED"]


async def test_download_survives_a_late_repeated_count(link):
    # MAVSDK re-sends MISSION_REQUEST_LIST after 0.5 s; the late first MISSION_COUNT then
    # restarts its download without clearing what it has (it returned item 0 twice) -- the kit
    # keeps one item per sequence number
    # the first count 0.7 s late: after MAVSDK's 0.5 s re-ask; before the pymavlink link's
    # 0.75 s one by 0.35 s rather than 0.05 s (a busy host could fire both timers at once)
    faults = Faults(delay_out={0: 0.7 if link == "mavsdk" else 0.4}, drop_out={3})
    async with (
        FakeVehicle(fence=PREVIOUS, faults=faults) as fake,
        open_vehicle(fake.url, timeout=5.0) as vehicle,
    ):
        got = await asyncio.wait_for(download_fence(vehicle), 6.0)
        assert same_items(PREVIOUS, got) == []
        # MAVSDK asked again after 0.5 s; the pymavlink link waits 0.75 s, and the count came
        assert len(fake.sent("MISSION_COUNT")) == (2 if link == "mavsdk" else 1)


# ------------------------------------------------------------------ uploads that succeed


async def test_upload_clean():
    async with FakeVehicle(fence=PREVIOUS) as fake:
        report, err = await upload_to(fake, NEW)
    assert err is None and report.verified and report.items == len(NEW)
    assert same_items(NEW, held(fake)) == []
    assert one_upload_accepted(fake)
    # nothing asked or sent twice: no timeout fired on either side
    assert fake.received("MISSION_COUNT") == [len(NEW)]
    assert fake.sent("MISSION_REQUEST") == fake.received("MISSION_ITEM_INT") == list(range(N))
    assert fake.received("MISSION_REQUEST_LIST") == [""]  # one read-back


N = len(NEW)  # outgoing mission messages: MISSION_REQUEST 0..N-1 are 0..N-1, the ACK is N


@pytest.mark.parametrize(
    "faults, what_is_lost",
    [
        (Faults(drop_in={0}), [("lost-in", "MISSION_COUNT", N)]),
        (Faults(drop_out={0}), [("lost-out", "MISSION_REQUEST", 0)]),
        (Faults(drop_out={4}), [("lost-out", "MISSION_REQUEST", 4)]),
        (Faults(drop_in={5}), [("lost-in", "MISSION_ITEM_INT", 4)]),
        (Faults(drop_in={N}), [("lost-in", "MISSION_ITEM_INT", N - 1)]),
        # the request and ArduPilot's re-ask a second later: the third ask still beats MAVSDK
        (Faults(drop_out={4, 5}), [("lost-out", "MISSION_REQUEST", 4)] * 2),
        # the vehicle stored the fence but its ACK is lost: MAVSDK times out, and the read-back
        # shows the fence sent, which is what success means
        (Faults(drop_out={N}), [("lost-out", "MISSION_ACK", "ACCEPTED")]),
        # the read-back loses its MISSION_COUNT; MAVSDK asks again
        (Faults(drop_out={N + 1}), [("lost-out", "MISSION_COUNT", N)]),
        (Faults(drop_in={N + 2}), [("lost-in", "MISSION_REQUEST_INT", 0)]),
    ],
    ids=[
        "count",
        "first-request",
        "request",
        "item",
        "last-item",
        "request-twice",
        "final-ack",
        "readback-count",
        "readback-request",
    ],
)
async def test_upload_survives_a_lost_message(faults, what_is_lost, link):
    async with FakeVehicle(fence=PREVIOUS, faults=faults) as fake:
        report, err = await upload_to(fake, NEW)
    # the pymavlink link's own re-send may be what the second numbered loss hits
    assert (
        lost(fake)[: 1 if link == "pymavlink" else None]
        == what_is_lost[: 1 if link == "pymavlink" else None]
    )
    assert err is None, str(err)
    assert report.verified
    assert same_items(NEW, held(fake)) == []
    # each loss made good by a re-send or a re-ask within the same upload, not by the vehicle
    # abandoning it and the kit waiting for that
    assert repaired(fake) == [] and one_upload_accepted(fake), fake.log


async def test_upload_survives_light_random_loss():
    # 5 % each way on a 30-item fence. Seed 7 loses items 0 and 3 of the upload and three
    # messages of the read-back, each loss alone in its step. Not every seed succeeds: of seeds
    # 0-11, 3 failed (cleanly), each after two or three losses in one item's exchange, which
    # MAVSDK does not survive (see the module docstring).
    items = polygon(30, r=0.004)
    faults = Faults(loss_in=0.05, loss_out=0.05, seed=7)
    async with FakeVehicle(fence=PREVIOUS, faults=faults) as fake:
        report, err = await upload_to(fake, items)
    assert len(lost(fake)) >= 2, fake.log
    assert err is None, str(err)
    assert same_items(items, held(fake)) == []
    assert repaired(fake) == [] and one_upload_accepted(fake), fake.log


async def test_upload_ignores_a_request_ahead():
    # ArduPilot never asks ahead, but a request for item 6 before item 3 is ignored by MAVSDK
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(extra_requests={3: 6})) as fake:
        report, err = await upload_to(fake, NEW)
    assert err is None, str(err)
    assert same_items(NEW, held(fake)) == []
    assert fake.sent("MISSION_REQUEST")[:5] == [0, 1, 2, 6, 3]


async def test_upload_survives_a_repeated_last_request():
    # the repeated last item arrives after the vehicle has finished: it answers ERROR, but
    # MAVSDK has already taken the ACCEPTED
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(duplicate_requests={N - 1})) as fake:
        report, err = await upload_to(fake, NEW)
    assert err is None, str(err)
    assert same_items(NEW, held(fake)) == []


# ------------------------------------------------------------------ uploads that fail cleanly


@pytest.mark.parametrize(
    "faults",
    [
        Faults(duplicate_requests={3}),  # the same request twice in a row
        Faults(extra_requests={4: 2}),  # a stale request for an item already received
    ],
    ids=["repeated-request", "stale-request"],
)
async def test_repeated_request(faults, link):
    # MAVSDK sends the item again, ArduPilot answers INVALID_SEQUENCE, MAVSDK stops (see the
    # docstring). The vehicle cancels the half-done upload after its timeout (8 s on ArduPilot;
    # 3 s here to keep the suite quick) and then the kit can read back what it holds. The
    # pymavlink link goes on past the INVALID_SEQUENCE, as ArduPilot does, and succeeds.
    async with FakeVehicle(fence=PREVIOUS, faults=faults, upload_timeout=3.0) as fake:
        report, err = await upload_to(fake, NEW)
    if link == "pymavlink":
        assert err is None and report.verified, str(err)
        assert same_items(NEW, held(fake)) == []
        assert "INVALID_SEQUENCE" in fake.sent("MISSION_ACK")  # it went past it
        return
    assert err is not None
    assert "out of step" in str(err)
    assert_upload_kept_old_fence(fake, err, says=["Fence upload timeout"])
    assert mav.MAV_MISSION_OPERATION_CANCELLED in fake.upload_results
    assert read_back_once_cancelled(fake), fake.log


async def test_item_lost_four_times(link):
    # incoming 0 is the count, 1..4 items 0..3, then item 4 and three re-sends: MAVSDK gives
    # up; the pymavlink link's own re-sends (at 0.75 s) and the vehicle's re-asks (every
    # second) send it a fifth time before the vehicle's 3 s timeout
    faults = Faults(drop_in={5, 6, 7, 8})
    async with FakeVehicle(fence=PREVIOUS, faults=faults, upload_timeout=3.0) as fake:
        report, err = await upload_to(fake, NEW)
    if link == "pymavlink":
        assert err is None and report.verified, str(err)
        assert same_items(NEW, held(fake)) == [] and len(lost(fake)) == 4
        assert repaired(fake) == [] and one_upload_accepted(fake), fake.log
        return
    assert err is not None
    assert "stopped answering" in str(err)
    assert_upload_kept_old_fence(fake, err, says=["Fence upload timeout"])
    assert read_back_once_cancelled(fake), fake.log


ERROR_CASES = [
    # (items, faults, words of the kit, the vehicle's own words)
    (polygon(80), Faults(), "no room", ["Only 70 items are supported"]),
    (polygon(70), Faults(), "refused the fence", ["Fence exceeds storage size"]),
    (
        polygon(5)[:2] + [replace(polygon(5)[2], param1=4.0)] + polygon(5)[3:],
        Faults(),
        "refused the fence",
        ["Unexpected vertex count want=5 got=4", "Fence validation failed"],
    ),
    (
        polygon(2) + polygon(3, lon0=14.5),
        Faults(),
        "refused the fence",
        ["Invalid vertex count (2)"],
    ),
    (polygon(4, param1=300), Faults(), "rejected an item as invalid", []),
    (
        NEW,
        Faults(nack_count=mav.MAV_MISSION_DENIED, nack_text="Upload refused while armed"),
        "denied the transfer",
        ["Upload refused while armed"],
    ),
    (
        NEW,
        Faults(nack_item=(4, mav.MAV_MISSION_INVALID_PARAM1), nack_text="Bad vertex count"),
        "rejected an item as invalid",
        ["Bad vertex count"],
    ),
    (
        NEW,
        Faults(nack_item=(6, mav.MAV_MISSION_NO_SPACE), nack_text="Out of memory for upload"),
        "no room",
        ["Out of memory for upload"],
    ),
]


@pytest.mark.parametrize(
    "items, faults, reason, says",
    ERROR_CASES,
    ids=[
        "too-many-items",
        "too-many-bytes",
        "vertex-counts",
        "two-vertices",
        "param1-over-255",
        "nack-count",
        "nack-item",
        "nack-no-space",
    ],
)
async def test_refused_upload_keeps_old_fence(items, faults, reason, says):
    async with FakeVehicle(fence=PREVIOUS, faults=faults) as fake:
        _, err = await upload_to(fake, items)
    assert err is not None
    msg = str(err)
    head = f"upload of {len(items)} fence items failed: "
    assert msg.startswith(head) and reason in msg.split(" | ")[0], msg
    assert "\n" not in msg
    for text in says:
        assert text in msg and text in err.vehicle_says, msg
    assert "still holds its previous fence (5 items)" in msg
    assert same_items(PREVIOUS, held(fake)) == [] and fake.fence_writes == 0
    # reported on the vehicle's refusal: the one upload ended there (no timeout on either
    # side) and the first read-back asked for was answered
    assert len(fake.upload_results) == 1 and "Fence upload timeout" not in fake.texts
    assert fake.received("MISSION_REQUEST_LIST") == [""]


async def test_stall_fails_cleanly_after_vehicle_timeout():
    # the vehicle stops asking after 3 items; MAVSDK gives up after 2.5 s, the vehicle cancels
    # 8 s after the last item (ArduPilot's timing), and only then answers the read-back
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(stall_after=3)) as fake:
        _, err = await upload_to(fake, NEW)
    assert err is not None
    assert "stopped answering" in str(err)
    assert_upload_kept_old_fence(fake, err, says=["Fence upload timeout"])
    assert fake.upload_results == [mav.MAV_MISSION_OPERATION_CANCELLED]
    assert read_back_once_cancelled(fake), fake.log


async def test_disconnect_mid_upload_fails_cleanly():
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(disconnect_after=3)) as fake:
        _, err = await upload_to(fake, NEW)
    assert err is not None and fake.disconnected
    msg = str(err)
    assert "stopped answering" in msg
    # no hang: the kit stopped asking once the heartbeats stopped, and said so
    assert_upload_kept_old_fence(
        fake, err, holds="no longer connected (no heartbeat), so what it holds is unknown"
    )


async def test_no_vehicle_is_a_link_error():
    async def connect():
        async with open_vehicle(f"udpin://127.0.0.1:{free_udp_port()}", timeout=1.0):
            pass

    # the link's own 1 s timeout ends it (the message names it); the deadline only stops a hang
    with pytest.raises(LinkError, match="no autopilot answered within 1 s"):
        await asyncio.wait_for(connect(), 30.0)
