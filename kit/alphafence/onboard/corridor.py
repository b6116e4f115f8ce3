"""Where the vehicle flies: the corridor in which the compiler counts what onboard fences cost.

A mission flies its legs in order — from home through every position it names, and straight
back home when it ends with RTL — so its *flight path* is that polyline, not a box around it.
The *corridor* is the airspace within the selection distance of the flight path (of the box,
for an operating area given as a box). The compiler keeps the fences that reach into the
corridor and, choosing how to store them, minimises the airspace *in the corridor* that the
onboard fence forbids beyond the full-resolution fences: a fence the path passes close to has
most of its surroundings in the corridor and gets a precise polygon; one at the corridor's
edge costs little there and gets a cheap shape. Area outside the corridor counts only
``LOSS_OUTSIDE`` as much, to break ties. The same quantity, over all onboard fences, is the
reported overshoot within the corridor (:class:`Overshoot`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.flights.mission import read_mission

LOSS_OUTSIDE = 1e-6  # what a square metre lost outside the corridor counts (ties only)


@dataclass
class Corridor:
    """The airspace within ``distance_m`` of the flight path (or of an area), metric.

    Attributes
    ----------
    path : shapely geometry
        The flight path (LineString, or Point for a single position) or the operating area
        (Polygon), in the compile's metric frame.
    distance_m : float
        The selection distance.
    area : shapely geometry
        ``path`` buffered by ``distance_m`` (empty when both have no area).
    """

    path: object
    distance_m: float
    area: object

    @classmethod
    def around(cls, path, distance_m: float) -> Corridor:
        """The corridor within ``distance_m`` of ``path`` (metric).

        Examples
        --------
        >>> import shapely
        >>> c = Corridor.around(shapely.LineString([(0, 0), (1000, 0)]), 100.0)
        >>> round(c.area.area / (2 * 100 * 1000 + math.pi * 100**2), 3)  # round ends, inscribed
        1.0
        """
        area = shapely.buffer(path, distance_m, quad_segs=16) if distance_m > 0 else path
        if area.area <= 0:
            area = shapely.Polygon()
        shapely.prepare(area)
        return cls(path, float(distance_m), area)

    @property
    def of_path(self) -> bool:
        """Whether it follows a flight path (rather than an area)."""
        return self.path.geom_type in ("LineString", "MultiLineString", "Point", "MultiPoint")

    def weighted_area(self, geoms):
        """The area of each geometry inside the corridor, plus ``LOSS_OUTSIDE`` times its
        whole area; the whole area when the corridor has none.

        Parameters
        ----------
        geoms : array_like of shapely geometries
            Metric.

        Returns
        -------
        ndarray of float

        Examples
        --------
        >>> import shapely
        >>> c = Corridor.around(shapely.box(0, 0, 10, 10), 0.0)
        >>> c.weighted_area([shapely.box(5, 0, 15, 10)]).round(6).tolist()
        [50.0001]
        """
        geoms = np.asarray(geoms, dtype=object)
        whole = shapely.area(geoms)
        if self.area.is_empty:
            return whole
        inside = np.zeros(len(geoms))
        covered = shapely.covers(self.area, geoms)
        mid = ~covered & shapely.intersects(self.area, geoms)
        inside[covered] = whole[covered]
        if mid.any():
            inside[mid] = shapely.area(shapely.intersection(geoms[mid], self.area))
        return inside + LOSS_OUTSIDE * whole


class LossModel:
    """What an onboard shape costs: the airspace it forbids beyond the full-resolution
    fences, weighted by the corridor (:meth:`Corridor.weighted_area`).

    Parameters
    ----------
    corridor : Corridor
    keep_out : list of shapely geometries
        The full-resolution keep-out fences compiled (metric).
    clear : LocalClear, optional
        Points no option may cover or come near (:mod:`alphafence.onboard.clear`): an option
        that does is no option.
    """

    def __init__(self, corridor: Corridor, keep_out, clear=None):
        self.corridor = corridor
        self.keep_out = np.asarray(keep_out, dtype=object)
        self.tree = shapely.STRtree(self.keep_out)
        self.clear = clear

    def _forbidden_near(self, geom):
        near = self.tree.query(geom)
        return shapely.union_all(self.keep_out[near]) if len(near) else shapely.Polygon()

    def rescore(self, piece) -> bool:
        """Re-count the loss of each of ``piece``'s options, keep the options that lose less
        than every cheaper one (and leave :attr:`clear`'s points clear), and choose the
        cheapest (in place). Whether any option is left.

        A keep-out option loses what it forbids beyond the full-resolution keep-out fences
        (a merged piece: the gap its merge closed, too);
        an inward keep-in option what it takes from the piece. An outward keep-in piece (the
        operator's operating area) is left alone.
        """
        if self.clear is not None and not self.clear.fit(piece):
            return False
        shapes = np.array([o.local for o in piece.options], dtype=object)
        if piece.inclusion:
            if piece.grows:
                return True
            lost = shapely.difference(piece.local, shapes)
        else:
            lost = shapely.difference(
                shapes, self._forbidden_near(shapely.box(*shapely.total_bounds(shapes)))
            )
        for o, loss in zip(piece.options, self.corridor.weighted_area(lost)):
            o.loss = float(loss)
        piece.options = frontier(piece.options)
        piece.choice = 0
        return True


def frontier(options):
    """Options by increasing cost, each losing strictly less than every cheaper one.

    Examples
    --------
    >>> from alphafence.onboard.options import Option
    >>> opts = [Option("polygon", 4, 34, 5.0, None), Option("circle", 1, 13, 5.0, None)]
    >>> [o.label for o in frontier(opts)]
    ['circle']
    """
    options = sorted(options, key=lambda o: (o.items, o.bytes, o.loss))
    out = []
    for o in options:
        if not out or o.loss < out[-1].loss - 1e-9:
            out.append(o)
    return out


@dataclass(frozen=True)
class Overshoot:
    """The onboard fence's overshoot within the corridor.

    ``added_m2 / fenced_m2``: the airspace in the corridor that the onboard fence forbids and
    the full-resolution fences allow, relative to the airspace in the corridor that the
    full-resolution fences forbid (keep-out fences, and what lies outside keep-in fences; the
    operator's own operating-area keep-in counts on neither side). 0 means the onboard fence
    forbids, in the corridor, exactly what the full-resolution fences do.

    Attributes
    ----------
    added_m2 : float
    fenced_m2 : float
    """

    added_m2: float
    fenced_m2: float

    @property
    def ratio(self) -> float:
        """``added_m2 / fenced_m2`` (NaN when nothing in the corridor is fenced)."""
        return self.added_m2 / self.fenced_m2 if self.fenced_m2 > 0 else math.nan


def forbidden(corridor: Corridor, keep_out, keep_in):
    """The airspace forbidden within the corridor (its whole extent when it has no area):
    inside any keep-out shape or outside any keep-in shape (ArduPilot's default), metric."""
    region = corridor.area
    if region.is_empty:
        region = shapely.envelope(shapely.union_all([*keep_out, *keep_in, corridor.path]))
    out = shapely.union_all(keep_out) if len(keep_out) else shapely.Polygon()
    if len(keep_in):
        out = shapely.union(out, shapely.difference(region, shapely.intersection_all(keep_in)))
    return shapely.intersection(out, region)


def overshoot(corridor: Corridor, onboard, full) -> Overshoot:
    """The :class:`Overshoot` of onboard shapes over full-resolution fences in the corridor.

    Parameters
    ----------
    corridor : Corridor
    onboard, full : tuple
        ``(keep_out, keep_in)`` lists of metric geometries each.

    Examples
    --------
    >>> import shapely
    >>> c = Corridor.around(shapely.box(0, 0, 100, 100), 0.0)
    >>> o = overshoot(c, ([shapely.box(0, 0, 20, 20)], []), ([shapely.box(0, 0, 10, 20)], []))
    >>> o.added_m2, o.fenced_m2, o.ratio
    (200.0, 200.0, 1.0)
    """
    on = forbidden(corridor, *onboard)
    fenced = forbidden(corridor, *full)
    return Overshoot(float(shapely.difference(on, fenced).area), float(fenced.area))


def flight_path(positions):
    """The flight path through ``(lon, lat)`` positions in order: a LineString, or a Point
    when they are all one position (positions within 1e-7 degrees of the one before are
    that position).

    Examples
    --------
    >>> flight_path([(14.5, 35.9), (14.6, 35.9), (14.5, 35.9)]).geom_type
    'LineString'
    >>> flight_path([(14.5, 35.9), (14.5, 35.9)]).geom_type
    'Point'
    """
    pts = np.asarray(positions, float).reshape(-1, 2)
    keep = np.r_[True, np.any(np.abs(np.diff(pts, axis=0)) > 1e-7, axis=1)]  # MAVLink's 1e-7°
    pts = pts[keep]
    return shapely.LineString(pts) if len(pts) > 1 else shapely.Point(pts[0])


def flight_path_from_plan(path):
    """The flight path of a mission: home, then every position it flies to in order, and
    home again where it returns to launch (RTL flies straight home), WGS84.

    Parameters
    ----------
    path : str or Path
        A QGroundControl ``.plan`` or a QGC WPL waypoint file.

    Returns
    -------
    shapely.LineString or shapely.Point
    """
    return flight_path([(w.lon, w.lat) for w in read_mission(path, min_positions=1)])
