"""Upload fences with the MAVLink mission protocol (fence type), read them back, compare.

Through MAVSDK's mission_raw plugin (raw MISSION_ITEM_INT items of mission type FENCE).
Success is claimed only when the fence downloaded after the upload matches what was sent,
item by item, to the 1e-7 degree. On failure the message says what the vehicle holds:
ArduPilot keeps its previous fence when an upload fails, and the kit checks that too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from kit.coords import from_e7, to_e7
from kit.writers.mavlink_items import FenceItem

MISSION_TYPE_FENCE = 1
FRAME_GLOBAL = 0

# MAVSDK's MissionRawResult names -> plain words
REASONS = {
    "TOO_MANY_MISSION_ITEMS": "the vehicle has no room for that many fence items",
    "TIMEOUT": "the vehicle stopped answering during the transfer",
    "INVALID_ARGUMENT": "the vehicle rejected an item as invalid",
    "UNSUPPORTED": "the vehicle does not support fence transfers",
    "DENIED": "the vehicle denied the transfer",
    "PROTOCOL_ERROR": "the transfer broke off (protocol error)",
    "INT_MESSAGES_NOT_SUPPORTED": "the vehicle does not speak MISSION_ITEM_INT",
    "TRANSFER_CANCELLED": "the transfer was cancelled",
    "BUSY": "the vehicle is busy with another transfer",
    "NO_SYSTEM": "the vehicle is not connected",
    "ERROR": "the vehicle refused the fence",
}


class FenceTransferError(RuntimeError):
    def __init__(self, message, vehicle_says=(), holds=None):
        self.vehicle_says = list(vehicle_says)
        self.holds = holds
        parts = [message]
        if self.vehicle_says:
            parts.append("vehicle: " + "; ".join(self.vehicle_says))
        if holds is not None:
            parts.append(holds)
        super().__init__(" | ".join(parts))


@dataclass
class UploadReport:
    items: int
    seconds: float
    verified: bool


def to_raw(items):
    from mavsdk.plugins.mission_raw import MissionItem

    return [
        MissionItem(seq=i, frame=FRAME_GLOBAL, command=it.command, current=0, autocontinue=1,
                    param1=float(it.param1), param2=0.0, param3=0.0, param4=0.0,
                    x=to_e7(it.lat), y=to_e7(it.lon), z=0.0, mission_type=MISSION_TYPE_FENCE)
        for i, it in enumerate(items)
    ]


def from_raw(raw):
    return [FenceItem(int(r.command), float(r.param1), from_e7(r.y), from_e7(r.x)) for r in raw]


def same_items(sent, got) -> list:
    """Differences between two item lists (empty when they match to 1e-7 degrees)."""
    diffs = []
    if len(sent) != len(got):
        diffs.append(f"{len(sent)} items sent, {len(got)} read back")
    for i, (a, b) in enumerate(zip(sent, got)):
        if a.command != b.command or abs(a.param1 - b.param1) > 1e-3 * max(1.0, abs(a.param1)) \
                or to_e7(a.lat) != to_e7(b.lat) or to_e7(a.lon) != to_e7(b.lon):
            diffs.append(f"item {i}: sent {a}, read {b}")
    return diffs


def _reason(exc) -> str:
    result = getattr(exc, "result", None)
    name = getattr(result, "name", str(result))
    return REASONS.get(name, f"transfer failed ({name})")


async def download_fence(vehicle):
    from mavsdk.plugins.mission_raw import MissionRawError

    try:
        raw = await vehicle.mission_raw.download_geofence()
    except MissionRawError as exc:
        if getattr(exc.result, "name", "") == "NO_MISSION_AVAILABLE":
            return []
        raise FenceTransferError(f"download failed: {_reason(exc)}") from None
    return from_raw(raw)


async def upload_fence(vehicle, items) -> UploadReport:
    """Upload, then download and compare. Raises FenceTransferError saying what failed and
    what the vehicle now holds."""
    from mavsdk.plugins.mission_raw import MissionRawError

    t0 = time.monotonic()
    try:
        await vehicle.mission_raw.upload_geofence(to_raw(items))
    except MissionRawError as exc:
        says = await vehicle.texts_since(t0)
        holds = await _what_it_holds(vehicle)
        raise FenceTransferError(f"upload of {len(items)} fence items failed: {_reason(exc)}", says, holds) from None
    got = await download_fence(vehicle)
    seconds = time.monotonic() - t0
    diffs = same_items(items, got)
    if diffs:
        raise FenceTransferError("the fence read back differs from the one sent: " + "; ".join(diffs[:3]),
                                 await vehicle.texts_since(t0, 0.0), f"the vehicle holds {len(got)} fence items")
    return UploadReport(len(items), seconds, True)


async def _what_it_holds(vehicle) -> str:
    try:
        got = await download_fence(vehicle)
    except FenceTransferError as exc:
        return f"could not read back what the vehicle holds ({exc})"
    return f"the vehicle still holds its previous fence ({len(got)} items)"
