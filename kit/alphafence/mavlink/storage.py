"""What fence items cost in ArduPilot's fence storage, and the storage each vehicle has.

ArduPilot (``AC_PolyFence_loader``) stores a fence as a 4-byte header, then per polygon 2 bytes
plus 8 a vertex, 13 bytes per circle, 9 for the return point, and a 1-byte end marker. Copter,
SITL and a Navio2 without ``BRD_SD_FENCE`` have 560 bytes (at most 70 items); Plane and Rover
672 (84 items). With ``BRD_SD_FENCE`` (kB, 1-64, read at boot; Linux boards such as the
Navio2, and SITL) the fence lives in a file, ``fence.stg`` in the vehicle's working directory,
of ``min(kB * 1024, 65535)`` bytes (``StorageAccess::attach_file``), which holds an eighth as
many items (``AC_PolyFence_loader::max_items``); a polygon still holds at most 255 vertices.

PX4 keeps each fence item in its own dataman slot, so only the item count is limited:
``GEOFENCE_MAX_VERTICES`` (64 on Linux boards, SITL and most flight controllers; 16 on the
memory-constrained ones). Measured on PX4 SITL: 64 items are accepted, 65 and more refused
with ``MAV_MISSION_NO_SPACE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.mavlink import ids  # not mavlink.items: the command line's parser reads PROFILES

HEADER_BYTES = 4
END_BYTES = 1
CIRCLE_BYTES = 13
RETURN_BYTES = 9


def polygon_bytes(n: int) -> int:
    """Bytes a polygon of ``n`` vertices takes in fence storage.

    Examples
    --------
    >>> polygon_bytes(69)
    554
    """
    return 2 + 8 * n


def storage_bytes(items) -> int:
    """Bytes ArduPilot needs to store these fence items (measured layout, AC_PolyFence_loader).

    Parameters
    ----------
    items : sequence of FenceItem
        Items in upload order (a polygon's vertices consecutive, each carrying the count).

    Returns
    -------
    int
        Header, items and end marker together.
    """
    total = HEADER_BYTES + END_BYTES
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in (
            ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
        ):
            n = int(it.param1)
            total += polygon_bytes(n)
            i += n
            continue
        total += RETURN_BYTES if it.command == ids.MAV_CMD_NAV_FENCE_RETURN_POINT else CIRCLE_BYTES
        i += 1
    return total


SD_FENCE_PARAM = "BRD_SD_FENCE"
"""ArduPilot's parameter for file-backed fence storage (kB; 0: the board's own storage)."""
SD_FENCE_MAX_KB = 64
FILE_MAX_BYTES = 0xFFFF  # StorageAccess::attach_file caps a file region at 65535 bytes
ITEM_BYTES = 8  # AC_PolyFence_loader::max_items: storage size / sizeof(Vector2l)


def file_storage_bytes(kb: int) -> int:
    """Bytes of fence storage ``BRD_SD_FENCE = kb`` gives (0 for 0).

    Examples
    --------
    >>> file_storage_bytes(32), file_storage_bytes(64)
    (32768, 65535)
    """
    return min(int(kb) * 1024, FILE_MAX_BYTES) if kb > 0 else 0


def sd_fence_kb_needed(items) -> int:
    """The least ``BRD_SD_FENCE`` (kB) whose file holds these items: their bytes, and eight
    bytes an item (ArduPilot's item limit).

    Parameters
    ----------
    items : sequence of FenceItem

    Returns
    -------
    int
        1 to 64, or more when no file storage can hold them.

    Examples
    --------
    >>> from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem
    >>> sd_fence_kb_needed([FenceItem(POLYGON_EXCLUSION, 255.0, 14.5, 35.9)] * 255 * 12)
    24
    """
    need = max(storage_bytes(items), ITEM_BYTES * len(items), 1)
    kb = math.ceil(need / 1024)
    return kb if file_storage_bytes(kb) >= need else kb + 1


@dataclass(frozen=True)
class Profile:
    """A vehicle's fence storage: the most items and bytes it accepts.

    Attributes
    ----------
    name : str
        The ``--profile`` name.
    items : int
        Most fence items the vehicle accepts in one upload.
    bytes : int
        Bytes of fence storage.
    max_polygon_vertices : int
        Most vertices of one polygon (ArduPilot's limit is 255).
    sd_fence_kb : int
        The ``BRD_SD_FENCE`` the storage assumes: 0 for the board's own storage.
    autopilot : str
        ``"ardupilot"`` or ``"px4"``: whose fence rules the items are compiled for
        (:mod:`alphafence.mavlink.autopilots`).
    """

    name: str
    items: int
    bytes: int
    max_polygon_vertices: int = 255
    sd_fence_kb: int = 0
    autopilot: str = "ardupilot"

    @property
    def file_backed(self) -> bool:
        """Whether the storage is a file (``BRD_SD_FENCE`` > 0) the vehicle must have."""
        return self.sd_fence_kb > 0


def navio2_profile(sd_fence_kb: int = SD_FENCE_MAX_KB) -> Profile:
    """The storage of ArduPilot on a Navio2 (or any Linux board, or SITL) with
    ``BRD_SD_FENCE = sd_fence_kb``: room for the full-resolution fences.

    Parameters
    ----------
    sd_fence_kb : int
        1 to 64 (kB).

    Raises
    ------
    ValueError
        Outside 1..64.

    Examples
    --------
    >>> p = navio2_profile()
    >>> p.items, p.bytes, p.sd_fence_kb
    (8191, 65535, 64)
    >>> navio2_profile(8).items
    1024
    """
    if not (isinstance(sd_fence_kb, int) and 1 <= sd_fence_kb <= SD_FENCE_MAX_KB):
        raise ValueError(f"BRD_SD_FENCE takes 1 to {SD_FENCE_MAX_KB} kB, not {sd_fence_kb!r}")
    size = file_storage_bytes(sd_fence_kb)
    return Profile("navio2", size // ITEM_BYTES, size, sd_fence_kb=sd_fence_kb)


PX4_ITEMS = 64
"""PX4's ``GEOFENCE_MAX_VERTICES`` on Linux boards (the Navio2), SITL and most flight
controllers: the most fence items it accepts (measured: 65 are refused)."""
PX4_CONSTRAINED_ITEMS = 16
"""The same on PX4's memory-constrained boards (``MEMORY_CONSTRAINED_SYSTEM``)."""
PX4_BYTES = 1 << 20  # no byte budget: one dataman slot an item; the count is the limit

BOARD_PROFILE = "copter"
"""The profile whose storage a vehicle without ``BRD_SD_FENCE`` is assumed to have (the
smallest: Copter, SITL and a Navio2 alike)."""

PROFILES = {
    "copter": Profile("copter", 70, 560),
    "plane": Profile("plane", 84, 672),
    "rover": Profile("rover", 84, 672),
    "sd-fence": Profile("sd-fence", 4096, 32 * 1024, sd_fence_kb=32),  # BRD_SD_FENCE = 32 (kB)
    "navio2": navio2_profile(),  # BRD_SD_FENCE = 64 (kB); other sizes: navio2_profile(kb)
    "px4": Profile("px4", PX4_ITEMS, PX4_BYTES, autopilot="px4"),
    "px4-constrained": Profile(
        "px4-constrained", PX4_CONSTRAINED_ITEMS, PX4_BYTES, autopilot="px4"
    ),
}
"""The storage profiles ``compile`` and ``upload --profile`` know."""

DEFAULT_PROFILE = {"ardupilot": "copter", "px4": "px4"}
"""The profile each autopilot's work assumes when no ``--profile`` is given."""


def vehicle_profile(
    profile: Profile | None, autopilot: str, whose: str = "the vehicle runs"
) -> Profile:
    """The storage to compile for on a vehicle running ``autopilot``: ``profile``, or without
    one the autopilot's default (:data:`DEFAULT_PROFILE`). ``whose`` says in the error what
    runs ``autopilot`` (``"the fence is for"``).

    Raises
    ------
    InputError
        ``profile`` is another autopilot's storage.

    Examples
    --------
    >>> vehicle_profile(None, "px4").name, vehicle_profile(PROFILES["navio2"], "ardupilot").name
    ('px4', 'navio2')
    """
    from alphafence.errors import InputError
    from alphafence.mavlink.autopilots import NAMES

    profile = profile or PROFILES[DEFAULT_PROFILE[autopilot]]
    if profile.autopilot != autopilot:
        fits = sorted(n for n, p in PROFILES.items() if p.autopilot == autopilot)
        raise InputError(
            "--profile",
            f"{profile.name} is {NAMES[profile.autopilot]}'s fence storage, and {whose} "
            f"{NAMES[autopilot]}: take one of {', '.join(fits)}",
        )
    return profile


MAX_FILE_ITEMS = FILE_MAX_BYTES // ITEM_BYTES
"""The most fence items any ArduPilot vehicle holds (8191: ``BRD_SD_FENCE = 64``)."""
