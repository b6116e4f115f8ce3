"""The room around a fully checked position: how far the vehicle may move before a full
check could say anything but CLEAR.

After a full check that found the vehicle CLEAR (inside no keep-out and no warning layer, and
inside every keep-in it must be in), two distances bound what the next positions can change:
``room_m``, the distance to the nearest fence *boundary* of any kind, in force or not (within
it no fence's inside or outside changes, so a keep-in holds the vehicle as it did), and
``keep_out_m``, the distance to the nearest keep-out in force at any altitude (the triangle
inequality: it shrinks by at most how far the vehicle moves). A fence with an altitude band
that holds the position could change with altitude alone: ``vertical_m`` is how far the
altitude may move before it reaches such a band's limit. :mod:`alphafence.awareness.reach`
turns these into the time a full check holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely


@dataclass(frozen=True)
class Clearance:
    """The room around one fully checked position.

    Attributes
    ----------
    x, y : float
        The position (metres, the fences' frame).
    room_m : float
        Its distance to the nearest fence boundary of any kind, in force or not.
    keep_out_m : float
        Its distance to the nearest keep-out in force, at any altitude (infinite when there
        is none).
    vertical_m : float
        How far its altitude may move before the band of a fence holding it is reached
        (infinite when no banded fence holds it).
    version : int
        The fences' ``version`` it was measured at.
    """

    x: float
    y: float
    room_m: float
    keep_out_m: float
    vertical_m: float
    version: int

    @classmethod
    def after(cls, fences, x: float, y: float, alt: float, check) -> Clearance | None:
        """The clearance of a position whose full check is ``check``, or None when it is in
        a keep-out or a warning layer or has left a keep-in (the next position is then
        checked in full).

        Parameters
        ----------
        fences : FenceSet
            The fences ``check`` was made against.
        x, y : float
            The position, metres in their frame.
        alt : float
            Metres above home.
        check : Check
            :meth:`FenceSet.check <alphafence.awareness.fenceset.FenceSet.check>`'s answer.
        """
        if check.inside_keep_out or check.inside_warning or check.outside_keep_in:
            return None
        room, vertical = measure_room(fences, x, y, alt)
        nearest = check.nearest_keep_out
        # at any altitude: the vehicle may climb or descend into a band before the next check
        keep_out = min(check.keep_out_any_m, nearest.distance_m if nearest else math.inf)
        return cls(x, y, room, keep_out, vertical, fences.version)

    def join(self, other: Clearance | None) -> Clearance | None:
        """The room both leave (another layer's, in the same frame at the same position)."""
        if other is None:
            return None
        return Clearance(
            self.x,
            self.y,
            min(self.room_m, other.room_m),
            min(self.keep_out_m, other.keep_out_m),
            min(self.vertical_m, other.vertical_m),
            self.version,
        )


def index_room(fences):
    """The STRtree of the fences' boundaries :func:`measure_room` asks (built once per frame:
    at 100,000 fences it takes a while, so the monitor builds it before the flight)."""
    cached = getattr(fences, "_room_tree", None)
    if cached is None or cached[0] is not fences.boundary:
        cached = (fences.boundary, shapely.STRtree(fences.boundary))
        fences._room_tree = cached
    return cached[1]


def measure_room(fences, x: float, y: float, alt: float) -> tuple[float, float]:
    """``(room_m, vertical_m)`` at a position of a :class:`~alphafence.awareness.fenceset.FenceSet`
    (see :class:`Clearance`).

    Examples
    --------
    >>> from alphafence.awareness.fenceset import FenceSet
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(14.5, 35.9)
    >>> box = frame.geom_to_wgs84(shapely.box(-100, -100, 100, 100))
    >>> fences = FenceSet([FenceRecord("a", "keep_in", box, alt_max_m=120.0)], frame=frame)
    >>> [round(v, 1) for v in measure_room(fences, 0.0, 60.0, 100.0)]
    [40.0, 20.0]
    >>> [round(v, 1) for v in measure_room(fences, 0.0, 160.0, 100.0)]
    [60.0, inf]
    """
    p = shapely.points((x, y))
    _, d = index_room(fences).query_nearest(p, return_distance=True)
    room = float(d[0]) if d.size else math.inf
    holding = fences.tree.query(p, predicate="intersects")  # at any altitude, in force or not
    if not holding.size:
        return room, math.inf
    gaps = np.abs(np.concatenate([fences.alt_min[holding], fences.alt_max[holding]]) - alt)
    gaps = gaps[np.isfinite(gaps)]
    return room, float(gaps.min()) if gaps.size else math.inf
