"""What fence items cost in ArduPilot's fence storage, and the storage each vehicle has.

ArduPilot (``AC_PolyFence_loader``) stores a fence as a 4-byte header, then per polygon 2 bytes
plus 8 a vertex, 13 bytes per circle, 9 for the return point, and a 1-byte end marker. Copter,
SITL and a Navio2 without ``BRD_SD_FENCE`` have 560 bytes (at most 70 items); Plane and Rover
672 (84 items). With ``BRD_SD_FENCE`` (Linux boards, SITL) the fence lives in a file of that
many kB.
"""

from __future__ import annotations

from dataclasses import dataclass

from alphafence.mavlink.items import POLYGON_EXCLUSION, POLYGON_INCLUSION, RETURN_POINT

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
        if it.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            n = int(it.param1)
            total += polygon_bytes(n)
            i += n
            continue
        total += RETURN_BYTES if it.command == RETURN_POINT else CIRCLE_BYTES
        i += 1
    return total


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
    """

    name: str
    items: int
    bytes: int
    max_polygon_vertices: int = 255


PROFILES = {
    "copter": Profile("copter", 70, 560),
    "plane": Profile("plane", 84, 672),
    "rover": Profile("rover", 84, 672),
    "sd-fence": Profile("sd-fence", 4096, 32 * 1024),  # BRD_SD_FENCE = 32 (kB)
}
"""The storage profiles ``compile`` and ``upload --profile`` know."""
