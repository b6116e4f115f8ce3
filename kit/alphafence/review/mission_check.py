"""A mission's legs checked against fences at their altitudes (``alphafence check-mission``).

Each leg flies the altitudes of its mission items' frame
(:mod:`alphafence.flights.mission_flight`) and meets each fence's band in the band's own
reference, as the monitor and the post-flight check compare them
(:class:`~alphafence.awareness.fenceset.FenceSet`, placed at the mission's home): legs relative
to home with limits above home, AMSL limits placed by home's altitude AMSL, AGL limits taken
above home (no terrain data); legs above the terrain with AGL limits only. What cannot be
compared is counted conservatively and said once in :attr:`MissionCheck.notes`: a limit AMSL
while home's altitude AMSL is not known, any but an AGL limit for a leg above the terrain, any
limit for a leg whose altitude is not known (within a keep-out fence's band throughout,
outside a keep-in fence's band). The geometry is :func:`alphafence.route.legs.check_legs`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from alphafence.awareness.fenceset import FenceSet
from alphafence.flights.mission import RTL_ALT_M, load_mission
from alphafence.route.legs import check_legs


@dataclass
class MissionCheck:
    """What :func:`check_mission` found.

    Attributes
    ----------
    issues : list of LegIssue
        By leg, then fence (keep-out fences first).
    legs : list of tuple
        ``(number, from, to)`` for every distinct leg (waypoints; ``to.profile`` holds the
        leg's altitudes), numbered from 1.
    warning_legs : set of int
        The legs that enter a warning layer within its band.
    notes : list of str
        What was counted conservatively, and what comparing the references approximates.
    home_amsl : float or None
        Home's altitude AMSL, where the mission gives it.
    """

    issues: list
    legs: list
    warning_legs: set
    notes: list = field(default_factory=list)
    home_amsl: float | None = None


def _numbers(legs):
    """Leg numbers as runs: ``"1-4, 7"``."""
    runs = []
    for n in sorted(legs):
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


AS_ANY = "counted within a keep-out fence's band, outside a keep-in fence's"


def _notes(fences, legs, home_amsl):
    """One sentence for each kind of leg or limit counted conservatively."""
    if fences is None:
        return []
    by_ref = {}
    for n, _, b in legs:
        by_ref.setdefault(b.frame if b.profile else None, []).append(n)
    notes = []
    if by_ref.get("home") and fences.amsl_sites and home_amsl is None:
        notes.append(
            "home's altitude AMSL is not known (the mission gives none, or 0): AMSL limits "
            f"cannot be placed for legs {_numbers(by_ref['home'])} ({AS_ANY})"
        )
    if by_ref.get("amsl"):
        notes.append(
            f"legs {_numbers(by_ref['amsl'])} fly AMSL altitudes and home's altitude AMSL is "
            f"not known: compared with AMSL limits only (the others {AS_ANY})"
        )
    if by_ref.get("terrain"):
        notes.append(
            f"legs {_numbers(by_ref['terrain'])} fly above the terrain (no terrain data here): "
            f"compared with AGL limits only (the others {AS_ANY})"
        )
    if by_ref.get(None):
        notes.append(
            f"legs {_numbers(by_ref[None])}: altitude not known (a frame other than relative, "
            "AMSL or terrain, a change of frame, or RTL from a height above the terrain): "
            f"{AS_ANY}"
        )
    if by_ref.get("home"):
        notes += fences.altitude_notes()
    return notes


def check_mission(mission, records, clearance=20.0, fence_label=None, rtl_alt_m=RTL_ALT_M):
    """Check every leg of a mission, at its altitudes, against the fences' bands in their own
    references (see the module).

    Parameters
    ----------
    mission : Mission or str or Path
        A mission (:func:`~alphafence.flights.mission.load_mission`), or its file.
    records : list of FenceRecord
    clearance : float
        Legs closer than this (metres) to a keep-out fence's volume, or to a keep-in fence's
        sides, floor or ceiling, are issues.
    fence_label : callable, optional
        Names a fence in the issues (default: site id and name).
    rtl_alt_m : float
        The altitude above home RTL climbs to at least (read from a file only).

    Returns
    -------
    MissionCheck

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> from alphafence.flights.mission import Mission, Waypoint
    >>> zone = FenceRecord("zone/1", "keep_out", shapely.box(14.500, 35.900, 14.502, 35.902),
    ...                    alt_min_m=120.0)
    >>> def at(alt):
    ...     return Mission([Waypoint("home", 14.497, 35.901, 0.0, "home"), Waypoint(
    ...         "item 1", 14.505, 35.901, alt, "home", ((0.0, alt), (1.0, alt)))])
    >>> check_mission(at(50.0), [zone]).issues
    []
    >>> [(i.fence, i.crosses) for i in check_mission(at(150.0), [zone]).issues]
    [('zone/1', True)]
    """
    if isinstance(mission, (str, Path)):
        mission = load_mission(mission, rtl_alt_m=rtl_alt_m)
    fences = None
    if any(r.alt_min_m is not None or r.alt_max_m is not None for r in records):
        fences = FenceSet(records)
        fences.set_home(mission.home_amsl)
    bands = fences.bands if fences is not None else None
    issues, legs, warning_legs = check_legs(
        mission.waypoints, records, clearance, fence_label, bands=bands
    )
    notes = _notes(fences, legs, mission.home_amsl)
    return MissionCheck(issues, legs, warning_legs, notes, mission.home_amsl)
