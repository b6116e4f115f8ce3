"""How ArduPilot combines the inclusion polygons and circles of the fence it holds.

``AC_PolyFence_loader::breached`` (ArduPilot's ``libraries/AC_Fence``): a position inside any
exclusion is a breach; of the inclusions, by default a position must lie inside **every**
polygon and circle (their intersection); with ``FENCE_OPTIONS`` bit 1 (``INCLUSION_UNION``,
value 2) inside at least one (their union). Two keep-in areas side by side, uploaded as two
inclusions without that bit, leave no airspace at all: the vehicle cannot arm, and in the air
its fence action fires at once.

Two or more inclusion items therefore need the union bit set on the vehicle; the kit sets it
when it uploads them (``alphafence upload``) and says so of the files it writes for others
(``.plan``, ``.waypoints``).

Examples
--------
>>> from alphafence.mavlink.items import FenceItem
>>> square = [FenceItem(5001, 4.0, x, y) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
>>> circle = FenceItem(5003, 100.0, 5.0, 5.0)
>>> inclusion_count(square + [circle]), needs_union(square + [circle]), needs_union(square)
(2, True, False)
>>> options_with_union(1), union_of(3), union_of(1)
(3, True, False)
"""

from __future__ import annotations

from alphafence.mavlink import ids

FENCE_OPTIONS = "FENCE_OPTIONS"  # AC_Fence's option bits (ArduPilot parameter)
INCLUSION_UNION = 2  # FENCE_OPTIONS bit 1: a position is inside when inside any inclusion
UNION_WORDS = "FENCE_OPTIONS bit 1 (value 2: union of inclusion areas)"


def inclusion_count(items) -> int:
    """How many inclusion polygons and circles a list of fence items holds (a polygon is its
    run of vertex items, each carrying the vertex count)."""
    n, k = 0, 0
    items = list(items)
    while k < len(items):
        it = items[k]
        if it.command == ids.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION:
            n += 1
        elif it.command == ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION:
            n += 1
            k += max(int(it.param1), 1)
            continue
        elif it.command == ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION:
            k += max(int(it.param1), 1)
            continue
        k += 1
    return n


def needs_union(items) -> bool:
    """Whether the items hold more than one inclusion: ArduPilot reads them as meant (inside
    any) only with :data:`INCLUSION_UNION` set in ``FENCE_OPTIONS``."""
    return inclusion_count(items) > 1


def union_of(options) -> bool:
    """Whether a ``FENCE_OPTIONS`` value reads inclusions as their union (None: the parameter
    is unknown, read as ArduPilot's default, the intersection)."""
    return options is not None and bool(int(options) & INCLUSION_UNION)


def options_with_union(options) -> int:
    """``FENCE_OPTIONS`` with the union bit set and its other bits kept."""
    return int(options or 0) | INCLUSION_UNION


def union_note(items) -> str | None:
    """What to tell whoever loads ``items`` into a vehicle by other means, when they hold more
    than one inclusion; None otherwise.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> union_note([FenceItem(5003, 50.0, 0, 0), FenceItem(5003, 50.0, 1, 1)])[:40]
    '2 inclusion areas: ArduPilot needs FENCE'
    """
    n = inclusion_count(items)
    if n < 2:
        return None
    return (
        f"{n} inclusion areas: ArduPilot needs {UNION_WORDS} to read them as meant, else it "
        "reads their intersection (alphafence upload sets it; with another tool, set it there)"
    )
