"""File-backed fence storage on the vehicle (``BRD_SD_FENCE``): checked before an upload, and
set, with a reboot, when asked.

ArduPilot on Linux boards (the Navio2) and SITL keeps its fence in a file of ``BRD_SD_FENCE``
kB when that is above 0; the parameter is read at boot, so a new size needs a reboot. A fence
that fits the board's own storage (the smallest: a Copter's 70 items, 560 bytes) needs none.
:func:`ensure_fence_storage` reads the parameter and, when the fence needs more, stops before
anything is sent, or (``reboot=True``, disarmed only) sets it, reads it back, reboots the
vehicle and reads it again.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

from alphafence.errors import VehicleError
from alphafence.mavlink.storage import (
    BOARD_PROFILE,
    PROFILES,
    SD_FENCE_MAX_KB,
    SD_FENCE_PARAM,
    sd_fence_kb_needed,
    storage_bytes,
)
from alphafence.vehicle.params import ParamError, apply_params, read_params
from alphafence.vehicle.reboot import RebootError, RebootReport, is_armed, reboot_vehicle


class StorageTooSmall(VehicleError):
    """The vehicle's fence storage is smaller than the fence.

    Attributes
    ----------
    have_kb, need_kb : int
        ``BRD_SD_FENCE`` on the vehicle, and what the fence needs.
    """

    def __init__(self, have_kb: int, need_kb: int):
        self.have_kb = have_kb
        self.need_kb = need_kb
        super().__init__(
            f"{SD_FENCE_PARAM} is {have_kb} kB on the vehicle; this fence needs {need_kb} kB: "
            f"set {SD_FENCE_PARAM} to at least {need_kb} and reboot the vehicle"
        )


@dataclass
class StorageReport:
    """What :func:`ensure_fence_storage` found and did.

    Attributes
    ----------
    have_kb : int
        ``BRD_SD_FENCE`` as first read.
    need_kb : int
        What the fence needs (0: it fits the board's own storage).
    set_kb : int or None
        The value set (None: left as it was).
    reboot : RebootReport or None
        The reboot, when there was one.
    """

    have_kb: int
    need_kb: int
    set_kb: int | None = None
    reboot: RebootReport | None = None


def kb_needed(items) -> int:
    """The ``BRD_SD_FENCE`` these items need: 0 when they fit the board's own storage (a
    Copter's, the smallest), else the least kB whose file holds them.

    Examples
    --------
    >>> from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem
    >>> kb_needed([FenceItem(POLYGON_EXCLUSION, 4.0, 14.5, 35.9)] * 4)
    0
    >>> kb_needed([FenceItem(POLYGON_EXCLUSION, 200.0, 14.5, 35.9)] * 200)
    2
    """
    board = PROFILES[BOARD_PROFILE]
    if len(items) <= board.items and storage_bytes(items) <= board.bytes:
        return 0
    return sd_fence_kb_needed(items)


async def read_sd_fence(vehicle, timeout: float = 0.0) -> int:
    """``BRD_SD_FENCE`` on the vehicle (kB), asking again until ``timeout`` seconds have
    passed (a vehicle just rebooted may not answer at once).

    Raises
    ------
    VehicleError
        When the vehicle has no such parameter (no file storage on this board) or does not
        answer.
    """
    deadline = time.monotonic() + timeout
    while True:
        try:
            got = await read_params(vehicle, [SD_FENCE_PARAM])
            return int(round(float(got[SD_FENCE_PARAM])))
        except ParamError as exc:
            if time.monotonic() >= deadline:
                raise VehicleError(
                    f"cannot read {SD_FENCE_PARAM} ({exc}): a board without it keeps its "
                    "fence in its own storage only; compile for that storage instead"
                ) from None
        await asyncio.sleep(0.5)


async def ensure_fence_storage(
    vehicle, items, sd_fence_kb: int, reboot: bool = False, say=None, timeout: float = 60.0
) -> StorageReport:
    """Make sure the vehicle's fence storage holds ``items`` before they are sent.

    Parameters
    ----------
    vehicle : Vehicle
    items : sequence of FenceItem
        The fence to upload.
    sd_fence_kb : int
        The size to set when the vehicle's is too small (at least what the fence needs is set).
    reboot : bool
        Set ``BRD_SD_FENCE`` and reboot when it is too small (refused while armed); else stop.
    say : callable, optional
        ``say(text)`` for each step.
    timeout : float
        Seconds the vehicle may take to come back from the reboot.

    Returns
    -------
    StorageReport

    Raises
    ------
    StorageTooSmall
        Too small and ``reboot`` not asked for: nothing was sent.
    RebootError
        The vehicle is armed (nothing was sent), or the reboot failed.
    VehicleError
        ``BRD_SD_FENCE`` cannot be read, set, or is still too small after the reboot.
    """
    say = say or (lambda text: None)
    need = kb_needed(items)
    have = await read_sd_fence(vehicle)
    if need == 0 or have >= need:
        return StorageReport(have, need)
    if need > SD_FENCE_MAX_KB:
        raise VehicleError(
            f"this fence needs {need} kB of fence storage; the most any vehicle has is "
            f"{SD_FENCE_MAX_KB} kB ({SD_FENCE_PARAM})"
        )
    if not reboot:
        raise StorageTooSmall(have, need)
    if await is_armed(vehicle):
        raise RebootError(
            f"{SD_FENCE_PARAM} is {have} kB on the vehicle and this fence needs {need} kB, "
            "but the vehicle is armed: it is rebooted only while disarmed"
        )
    target = max(need, min(int(sd_fence_kb), SD_FENCE_MAX_KB))
    await apply_params(vehicle, {SD_FENCE_PARAM: target})
    say(f"{SD_FENCE_PARAM} set to {target} kB (was {have}); rebooting the vehicle")
    rep = await reboot_vehicle(vehicle, timeout)
    after = await read_sd_fence(vehicle, timeout=10.0)
    say(
        f"the vehicle rebooted and was back {rep.back_s:.1f} s after the command; "
        f"{SD_FENCE_PARAM} is {after} kB"
    )
    if after < need:
        raise VehicleError(
            f"{SD_FENCE_PARAM} reads {after} kB after the reboot; this fence needs {need} kB"
        )
    return StorageReport(have, need, target, rep)
