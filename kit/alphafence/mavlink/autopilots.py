"""What differs between the autopilots the kit compiles fences for: ArduPilot and PX4.

Both take the fence with the MAVLink mission protocol (mission_type FENCE) and read a polygon's
edges as straight lines in lat/lon; they differ in what they do with it:

==========================  ==================================  ==================================
                            ArduPilot (``AC_Fence``)            PX4 (``navigator/geofence.cpp``)
==========================  ==================================  ==================================
storage                     bytes (560 to 64 kB)                items (64; 16 on small boards)
several inclusions          their intersection, or with         always their intersection
                            ``FENCE_OPTIONS`` bit 1 their union
home outside an inclusion   refuses to arm                      discards **that area** when the
(or inside an exclusion)                                        fence loads, silently (a log
                                                                line), and arms without it
return point                kept (``FENCE_RETURN_POINT``)       ignored
circle distance             flat earth on its integers          its local projection (an
                            (:mod:`~alphafence.geo.vehicle_distance`)  azimuthal equidistant one on a
                                                                6,371 km sphere)
action                      ``FENCE_ACTION``                    ``GF_ACTION``
==========================  ==================================  ==================================

Examples
--------
>>> autopilot_of(12), autopilot_of(3), autopilot_of(8)
('px4', 'ardupilot', None)
>>> keeps_return_point("px4"), inclusion_union_possible("ardupilot")
(False, True)
"""

from __future__ import annotations

from alphafence.mavlink import ids

ARDUPILOT = "ardupilot"
PX4 = "px4"
AUTOPILOTS = (ARDUPILOT, PX4)
"""The autopilots the kit compiles for (``--autopilot``)."""

NAMES = {ARDUPILOT: "ArduPilot", PX4: "PX4"}
"""How messages name each."""

_BY_HEARTBEAT = {ids.MAV_AUTOPILOT_ARDUPILOTMEGA: ARDUPILOT, ids.MAV_AUTOPILOT_PX4: PX4}


def autopilot_of(mav_autopilot: int) -> str | None:
    """The autopilot a HEARTBEAT's ``autopilot`` field names, or None for another one."""
    return _BY_HEARTBEAT.get(int(mav_autopilot))


def keeps_return_point(autopilot: str) -> bool:
    """Whether the autopilot uses a fence return point (PX4 skips the item)."""
    return autopilot == ARDUPILOT


def inclusion_union_possible(autopilot: str) -> bool:
    """Whether the autopilot can read several inclusions as their union (ArduPilot, with
    ``FENCE_OPTIONS`` bit 1); PX4 reads them as their intersection, always."""
    return autopilot == ARDUPILOT


def check_autopilot(name: str) -> str:
    """``name`` if it is an autopilot the kit knows, else ValueError."""
    if name not in AUTOPILOTS:
        raise ValueError(f"autopilot {name!r}: the kit knows {', '.join(AUTOPILOTS)}")
    return name
