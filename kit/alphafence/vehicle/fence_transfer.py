"""Upload fences with the MAVLink mission protocol (fence type), read them back, compare.

Through the vehicle link's fence transfer (MAVSDK's mission_raw plugin, or the pymavlink link's
own mission protocol: MISSION_ITEM_INT items of mission type FENCE).
Success is claimed only when the fence downloaded after the upload matches what was sent,
item by item, to the 1e-7 degree. On failure the message says what the vehicle holds:
ArduPilot keeps its previous fence when an upload fails, and the kit checks that too.
"""

from __future__ import annotations

import asyncio
import difflib
import math
import time
from dataclasses import dataclass

from alphafence.errors import InputError, VehicleError
from alphafence.geo.coords import from_e7, to_e7
from alphafence.mavlink import ids
from alphafence.mavlink.items import (
    FenceItem,
)
from alphafence.mavlink.storage import MAX_FILE_ITEMS
from alphafence.onboard.decode import decode_fence
from alphafence.vehicle.values import TransferFailed

# ArduPilot abandons a stalled upload 8 s after the last item it received, and until then answers
# a download with MISSION_ACK(DENIED), which MAVSDK's download ignores (it times out instead).
# MAVSDK gives up on an upload after about 2.5 s of silence: the vehicle may need the rest of
# those 8 s before it can say what it holds.
VEHICLE_UPLOAD_TIMEOUT_S = 8.0

# MAVSDK's MissionRawResult names (both links report these) -> plain words
REASONS = {
    "TOO_MANY_MISSION_ITEMS": "the vehicle has no room for that many fence items",
    "TIMEOUT": "the vehicle stopped answering during the transfer",
    "INVALID_ARGUMENT": "the vehicle rejected an item as invalid",
    "UNSUPPORTED": "the vehicle does not support fence transfers",
    "DENIED": "the vehicle denied the transfer",
    # MAVSDK's name for MISSION_ACK(MAV_MISSION_ERROR), ArduPilot's answer to a fence it will
    # not store (too many bytes, a bad polygon, ...), and for an ACK before the last item
    "PROTOCOL_ERROR": "the vehicle refused the fence",
    "INT_MESSAGES_NOT_SUPPORTED": "the vehicle does not speak MISSION_ITEM_INT",
    "TRANSFER_CANCELLED": "the transfer was cancelled",
    "BUSY": "the vehicle is busy with another transfer",
    "NO_SYSTEM": "the vehicle is not connected",
    # MAVSDK's name for a message it could not send (its ConnectionError)
    "ERROR": "the link to the vehicle failed",
    # ArduPilot answers an item it did not ask for (a repeated or late request) with
    # MISSION_ACK(INVALID_SEQUENCE), and MAVSDK ends the upload there
    "INVALID_SEQUENCE": "the transfer got out of step (a message was repeated or came late)",
    "NO_MISSION_AVAILABLE": "there were no fence items to send",
    "COUNT_TOO_LARGE": "the vehicle announced more fence items than its storage holds",
}


class FenceTransferError(VehicleError):
    """A fence transfer failed, or what was read back is not what was sent.

    Parameters
    ----------
    message : str
        What failed.
    vehicle_says : iterable of str
        The vehicle's STATUSTEXTs around the failure (each made one line).
    holds : str, optional
        What the vehicle holds now, in words.
    result : str, optional
        MAVSDK's ``MissionRawResult`` name, when MAVSDK gave one.
    """

    def __init__(self, message, vehicle_says=(), holds=None, result=None):
        self.result = result  # MAVSDK's MissionRawResult name, when MAVSDK gave one
        self.vehicle_says = [" ".join(str(t).split()) for t in vehicle_says]  # one line
        self.holds = holds
        parts = [message]
        if self.vehicle_says:
            parts.append("vehicle: " + "; ".join(self.vehicle_says))
        if holds is not None:
            parts.append(holds)
        super().__init__(" | ".join(parts))


@dataclass
class UploadReport:
    """A verified upload: how many items, how long it took (upload and read-back)."""

    items: int
    seconds: float
    verified: bool


MAX_DOWNLOAD_ITEMS = MAX_FILE_ITEMS
"""The most fence items a download may bring unless the caller knows the vehicle's storage:
what the largest storage ArduPilot has holds (``BRD_SD_FENCE = 64``: 65535 bytes, 8191
items). A vehicle claiming more is refused before the items are checked one by one, so a
faulty or hostile count cannot make the kit hold and check an unbounded list."""


def from_raw(raw, max_items: int = MAX_DOWNLOAD_ITEMS):
    """The vehicle's items as FenceItems, after checking every one: what comes over the link
    is input like any file (a faulty or hostile vehicle, a corrupted link), so an item out of
    range, of another mission type, or a polygon whose vertex counts disagree is refused with
    one line saying which item and what is wrong.

    Parameters
    ----------
    raw : sequence
        MAVSDK's ``mission_raw`` items.
    max_items : int
        More items than this are refused at once (the storage's capacity).
    """
    if len(raw) > max_items:
        raise FenceTransferError(_too_many(len(raw), max_items))
    items = [_raw_item(i, r) for i, r in enumerate(raw)]
    try:  # positions, commands, radii, vertex counts, polygons: checked where items are decoded
        decode_fence(items, INVALID)
    except InputError as exc:
        raise FenceTransferError(str(exc)) from None
    return items


INVALID = "the vehicle sent an invalid fence"


def _too_many(n, max_items) -> str:
    return f"the vehicle sent {n} fence items (over {max_items}, more than its fence storage holds)"


def _raw_item(i, r):
    """One MAVSDK raw item as a FenceItem: numeric fields, of the fence mission type."""
    try:
        command, mission_type = int(r.command), int(r.mission_type)
        x, y, param1 = int(r.x), int(r.y), float(r.param1)
    except (TypeError, ValueError, OverflowError):
        raise FenceTransferError(f"{INVALID}: item {i}: a field is not a number") from None
    if mission_type != ids.MAV_MISSION_TYPE_FENCE:
        raise FenceTransferError(
            f"{INVALID}: item {i}: mission type {mission_type}, not a fence item "
            f"({ids.MAV_MISSION_TYPE_FENCE})"
        )
    if not math.isfinite(param1):
        raise FenceTransferError(f"{INVALID}: item {i}: parameter 1 is {param1}")
    return FenceItem(command, param1, from_e7(y), from_e7(x))


def same_items(sent, got) -> list:
    """Differences between two item lists, empty when they match (positions to 1e-7 degrees).

    Items are lined up by command and position (difflib's matching), so an item left out or
    added is named as such and the items after it are not reported as changed: the counts
    when they differ, then each item sent and not read back, read back and not sent, or read
    back different (by its number in each list when the numbers differ).

    Parameters
    ----------
    sent, got : sequence of FenceItem

    Returns
    -------
    list of str
        One line per difference.

    Examples
    --------
    >>> a, b, c = (FenceItem(5003, 50.0, 14.5, lat) for lat in (35.9, 35.91, 35.92))
    >>> for line in same_items([a, b, c], [a, c]):
    ...     print(line)
    3 items sent, 2 read back
    item 1 not read back: FenceItem(command=5003, param1=50.0, lon=14.5, lat=35.91)
    >>> same_items([a, b, c], [a, b, FenceItem(5003, 50.0, 14.5, 35.9200001)])[0][:48]
    'item 2: sent FenceItem(command=5003, param1=50.0'
    """
    diffs = []
    if len(sent) != len(got):
        diffs.append(f"{len(sent)} items sent, {len(got)} read back")
    keys = [[(int(it.command), to_e7(it.lat), to_e7(it.lon)) for it in seq] for seq in (sent, got)]
    matcher = difflib.SequenceMatcher(None, *keys, autojunk=False)
    for _, i1, i2, j1, j2 in matcher.get_opcodes():
        n = min(i2 - i1, j2 - j1)  # replaced (or equal) items, paired in order
        for i, j in zip(range(i1, i1 + n), range(j1, j1 + n)):
            a, b = sent[i], got[j]
            if keys[0][i] != keys[1][j] or not _same_param1(a.param1, b.param1):
                read = f"read {b}" if i == j else f"read as item {j}: {b}"
                diffs.append(f"item {i}: sent {a}, {read}")
        diffs += [f"item {i} not read back: {sent[i]}" for i in range(i1 + n, i2)]
        diffs += [f"read item {j} was not sent: {got[j]}" for j in range(j1 + n, j2)]
    return diffs


def _same_param1(a, b) -> bool:
    """Vertex counts equal, radii to 0.1 % (the vehicle keeps a float)."""
    return abs(a - b) <= 1e-3 * max(1.0, abs(a))


def _result_name(exc) -> str:
    return str(exc.result)


def _reason(exc) -> str:
    name = _result_name(exc)
    return REASONS.get(name, f"transfer failed ({name})")


async def download_fence(vehicle, max_items: int = MAX_DOWNLOAD_ITEMS):
    """The fence the vehicle holds, as checked FenceItems ([] when it holds none).

    Parameters
    ----------
    vehicle : Vehicle
    max_items : int
        The most items the vehicle's storage holds (default: the largest ArduPilot has);
        a download of more is refused.

    Raises
    ------
    FenceTransferError
        When the download fails or what came is not a valid fence.
    """
    try:
        raw = await vehicle.download_geofence(max_items)
    except TransferFailed as exc:
        if exc.result == "COUNT_TOO_LARGE":  # refused before any item was asked for
            raise FenceTransferError(_too_many(exc.detail, max_items)) from None
        raise FenceTransferError(
            f"download failed: {_reason(exc)}", result=_result_name(exc)
        ) from None
    return from_raw(_in_sequence(raw), max_items)


def _in_sequence(raw):
    """The downloaded items, one per sequence number 0..n-1.

    MAVSDK 4.1 keeps the items it already has when a repeated MISSION_COUNT (an answer to its
    own re-sent MISSION_REQUEST_LIST, arriving late) restarts a download, and then returns some
    items twice; ArduPilot sends the same item for the same number, so one per number is kept."""
    by_seq = {}
    for r in raw:
        by_seq.setdefault(int(r.seq), r)
    if sorted(by_seq) != list(range(len(by_seq))):
        raise FenceTransferError(f"download failed: items came back numbered {sorted(by_seq)}")
    return [by_seq[i] for i in range(len(by_seq))]


SHOWN_DIFFS = 4  # differences a read-back that differs names (then how many more)


async def upload_fence(vehicle, items, capacity: int | None = None) -> UploadReport:
    """Upload, then download and compare.

    Parameters
    ----------
    vehicle : Vehicle
    items : sequence of FenceItem
    capacity : int, optional
        The most items the vehicle's storage holds (a profile's ``items``): a read-back of
        more (and more than were sent) is refused before its items are checked; default: the
        largest storage ArduPilot has.

    Raises
    ------
    FenceTransferError
        Saying what failed and what the vehicle now holds.
    """
    bound = max(len(items), MAX_DOWNLOAD_ITEMS if capacity is None else capacity)
    t0 = time.monotonic()
    try:
        await vehicle.upload_geofence(items)
    except TransferFailed as exc:
        got, holds = await _what_it_holds(vehicle, bound)
        if got is not None and same_items(items, got) == []:
            # the vehicle stored the fence but its final MISSION_ACK was lost: the read-back,
            # which is what success means here, shows the fence sent
            return UploadReport(len(items), time.monotonic() - t0, True)
        says = await vehicle.texts_since(t0)
        raise FenceTransferError(
            f"upload of {len(items)} fence items failed: {_reason(exc)}",
            says,
            holds,
            result=_result_name(exc),
        ) from None
    got = await download_fence(vehicle, bound)
    seconds = time.monotonic() - t0
    diffs = same_items(items, got)
    if diffs:
        if len(diffs) > SHOWN_DIFFS:
            diffs[SHOWN_DIFFS:] = [f"and {len(diffs) - SHOWN_DIFFS} more differences"]
        raise FenceTransferError(
            "the fence read back differs from the one sent: " + "; ".join(diffs),
            await vehicle.texts_since(t0, 0.0),
            f"the vehicle holds {len(got)} fence items",
        )
    return UploadReport(len(items), seconds, True)


async def _what_it_holds(vehicle, max_items=MAX_DOWNLOAD_ITEMS):
    """After a failed upload: (items read back or None, what the vehicle holds in words).

    Keeps asking while the vehicle may still be busy with the abandoned upload (see
    VEHICLE_UPLOAD_TIMEOUT_S) and still sends heartbeats; each attempt ends within MAVSDK's
    own timeout (about 2.5 s), so this takes at most about 11 s."""
    deadline = time.monotonic() + VEHICLE_UPLOAD_TIMEOUT_S + 0.5
    while True:
        try:
            got = await download_fence(vehicle, max_items)
        except FenceTransferError as exc:
            why = str(exc)
        else:
            return got, f"the vehicle still holds its previous fence ({len(got)} items)"
        if not await _connected(vehicle):
            return None, (
                "the vehicle is no longer connected (no heartbeat), so what it holds "
                "is unknown; ArduPilot keeps its previous fence when an upload fails"
            )
        if time.monotonic() >= deadline:
            return None, f"could not read back what the vehicle holds ({why})"
        await asyncio.sleep(0.1)


async def _connected(vehicle) -> bool:
    try:
        return bool(await vehicle.is_connected())
    except Exception:  # no way to tell: keep asking until the deadline
        return True
