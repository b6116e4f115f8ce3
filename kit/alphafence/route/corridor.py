"""Routing over the fences that can matter: a corridor around the line from start to goal.

A national fence file holds hundreds of fences, some perhaps on another continent; one
:class:`~alphafence.route.roadmap.Roadmap` over all of them is a Voronoi diagram of millions
of points (minutes of one scipy call, which Ctrl-C cannot stop). :class:`CorridorPlanner`
builds its roadmap over the keep-out fences and warning layers within a corridor around the
segment from start to goal only (one STRtree ``dwithin`` query), routes on it, and checks the
route against every fence within reach (another STRtree query):

* the route keeps the clearance from every fence: it is the answer;
* it comes within the clearance of fences outside the corridor: the corridor doubles its
  width (at least enough to take those fences in) and the planner routes again;
* the corridor's roadmap has no route: there is none, since fences left out can only block
  more (a roadmap covers its fences with a free margin all round).

Everything is in metres of one local frame centred between start and goal (a
:class:`FenceView`), the fences read as ArduPilot reads them (edges straight in lon/lat);
fences farther than ``REACH_M`` from its centre, where the frame no longer serves, are out of
reach. The route's legs are then split where their lon/lat reading, the line ArduPilot flies,
would come closer to a fence than the clearance (:func:`~alphafence.route.planner.split_legs`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.planner import (
    FLOWN_SLACK_M,
    READ_M,
    fence_label,
    flown_distance,
    read_legs,
    split_legs,
)
from alphafence.route.roadmap import EPS_CLEAR, Roadmap, Route

KINDS = ("keep_out", "warning", "keep_in")
REACH_M = 5_000_000.0  # fences farther than this from the frame's centre are left out
CHUNK = 20_000  # geometries projected per call, so that Ctrl-C is heard between calls


@dataclass
class Corridor:
    """One corridor a :class:`CorridorPlanner` routed in.

    Attributes
    ----------
    number : int
        1 for the first, 2 for the next (wider) one...
    half_width_m : float
        Fences within this distance of the segment from start to goal are in it.
    fences : ndarray of int
        Its keep-out fences, as indices into ``CorridorPlanner.keep_out``.
    warnings : ndarray of int
        Its warning layers, as indices into ``CorridorPlanner.warning``.
    total : int
        Keep-out fences within reach, in the corridor or not.
    outside : int
        Fences outside the corridor that its route came closer to than the clearance (then
        the planner tried a wider corridor).
    """

    number: int
    half_width_m: float
    fences: np.ndarray
    warnings: np.ndarray
    total: int
    outside: int = 0


def project(frame, geoms, reach=REACH_M, chunk=CHUNK):
    """WGS84 geometries in the metres of ``frame`` as their readers mean them (edges straight
    in lon/lat, followed to within ``READ_M``), a chunk at a time, and which are in reach.

    Parameters
    ----------
    frame : LocalFrame
    geoms : sequence of shapely geometry
        Lon, lat.
    reach : float
        A geometry with a vertex farther than this from the frame's centre (or none that
        projects to a finite position) is out of reach.
    chunk : int
        Geometries a call.

    Returns
    -------
    local : ndarray of shapely geometry
        Every geometry, metres.
    in_reach : ndarray of bool

    Examples
    --------
    >>> import shapely
    >>> frame = LocalFrame(14.5, 35.9)
    >>> near, far = shapely.box(14.5, 35.9, 14.51, 35.91), shapely.box(-165.5, -35.9, -165.4, -35.8)
    >>> local, ok = project(frame, [near, far])
    >>> ok.tolist(), round(local[0].area / 1e6, 2)
    ([True, False], 1.0)
    """
    geoms = np.asarray(list(geoms), dtype=object)
    local = np.empty(len(geoms), dtype=object)
    ok = np.zeros(len(geoms), bool)
    for i in range(0, len(geoms), chunk):
        part = frame.read_geom(geoms[i : i + chunk], READ_M)
        local[i : i + chunk] = part
        xy, index = shapely.get_coordinates(part, return_index=True)
        far = ~(np.hypot(xy[:, 0], xy[:, 1]) <= reach)  # NaN is far too
        good = ~shapely.is_empty(part)
        good[np.unique(index[far])] = False
        ok[i : i + chunk] = good
    return local, ok


class FenceView:
    """The fences of ``records`` within reach of ``frame``, read as ArduPilot reads them, with
    what routing asks of them: clear positions and segments, legs as flown.

    Parameters
    ----------
    records : list of FenceRecord
        Keep-out fences, warning layers and keep-in fences.
    frame : LocalFrame
    clearance : float
        Least distance from any keep-out fence, metres.

    Attributes
    ----------
    keep_out, warning, keep_in : ndarray of shapely geometry
        The fences of each kind within reach, metres.
    keep_out_records, keep_in_records : list of FenceRecord
        One per ``keep_out``, ``keep_in``.
    out_of_reach : int
        Keep-out fences and warning layers left out.
    ce : float
        The clearance plus ``EPS_CLEAR``: what routes keep.
    tree : STRtree
        Over ``keep_out``.

    Examples
    --------
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> frame = LocalFrame(14.5, 35.9)
    >>> box = FenceRecord("x", "keep_out", frame.geom_to_wgs84(shapely.box(0, 0, 100, 100)))
    >>> FenceView([box], frame, 20.0).point_clear([(50, 119), (50, 121)]).tolist()
    [False, True]
    """

    def __init__(self, records, frame, clearance=20.0):
        self.frame = frame
        self.clearance = float(clearance)
        self.ce = self.clearance + EPS_CLEAR
        ko, wa, ki = ([r for r in records if r.kind == k] for k in KINDS)
        ko_local, ko_ok = project(frame, [r.geometry for r in ko])
        wa_local, wa_ok = project(frame, [r.geometry for r in wa])
        ki_local, ki_ok = project(frame, [r.geometry for r in ki])
        self.out_of_reach = int((~ko_ok).sum() + (~wa_ok).sum())
        self.keep_out_records = [ko[i] for i in np.flatnonzero(ko_ok)]
        self.keep_in_records = [ki[i] for i in np.flatnonzero(ki_ok)]
        self.keep_out = shapely.make_valid(ko_local[ko_ok])
        self.warning = wa_local[wa_ok]
        self.keep_in = shapely.make_valid(ki_local[ki_ok])
        self.tree = shapely.STRtree(self.keep_out)
        self.wtree = shapely.STRtree(self.warning)
        shapely.prepare(self.keep_in)

    def to_xy(self, lonlat):
        """A ``(lon, lat)`` position in the frame's metres, as an array ``[x, y]``."""
        x, y = self.frame.to_local(float(lonlat[0]), float(lonlat[1]))
        return np.array([float(x), float(y)])

    def to_lonlat(self, xy):
        """``[x, y]`` metres in the frame -> ``(lon, lat)``."""
        lon, lat = self.frame.to_wgs84(float(xy[0]), float(xy[1]))
        return (float(lon), float(lat))

    def point_clear(self, xy):
        """Boolean per point (metres): at least ``ce`` from every keep-out fence."""
        pts = shapely.points(np.asarray(xy, float).reshape(-1, 2))
        ok = np.ones(len(pts), bool)
        ok[self.tree.query(pts, predicate="dwithin", distance=self.ce)[0]] = False
        return ok

    def clear(self, a, b):
        """Boolean per straight segment ``a[i]``-``b[i]`` (metres): at least ``ce`` from every
        keep-out fence."""
        a = np.asarray(a, float).reshape(-1, 2)
        b = np.asarray(b, float).reshape(-1, 2)
        segs = shapely.linestrings(np.stack([a, b], axis=1))
        ok = np.ones(len(segs), bool)
        ok[self.tree.query(segs, predicate="dwithin", distance=self.ce)[0]] = False
        return ok

    def at_fault(self, readings, chords):
        """Boolean per leg: its lon/lat reading comes closer than the clearance (plus
        ``FLOWN_SLACK_M``) to a keep-out fence, or leaves a keep-in fence that holds its
        chord (see :func:`~alphafence.route.planner.split_legs`)."""
        fault = np.zeros(len(readings), bool)
        near = self.clearance + FLOWN_SLACK_M
        fault[self.tree.query(readings, predicate="dwithin", distance=near)[0]] = True
        for area in self.keep_in:
            fault |= shapely.covers(area, chords) & ~shapely.covers(area, readings)
        return fault

    def flown(self, xy, lonlat):
        """The route through ``xy`` (metres) and ``lonlat`` with its legs split where their
        lon/lat reading is at fault (:meth:`at_fault`): ``(xy, lonlat, readings)``."""
        xy, lonlat = split_legs(self.frame, xy, lonlat, self.at_fault)
        return xy, lonlat, read_legs(self.frame, lonlat)


class CorridorPlanner:
    """Routes from ``start`` to ``goal`` over only the fences in a corridor around them,
    widening it while the route comes too close to a fence left out.

    Parameters
    ----------
    records : list of FenceRecord
        Keep-out fences are avoided, warning layers cost more; keep-in fences are not routed
        round (a leg is only split so that, flown, it stays in those that hold it).
    start, goal : tuple of float
        ``(lon, lat)``.
    clearance : float
        Least distance from any keep-out fence, metres.
    half_width : float, optional
        The first corridor's: fences within this many metres of the segment from start to
        goal. Default a quarter of the distance plus twenty times the clearance.
    view : FenceView, optional
        The fences already read into a frame that serves start and goal; ``records`` and
        ``clearance`` are then not used. By default a view of ``records`` in a frame centred
        between start and goal.
    **roadmap_options
        Passed to every :class:`Roadmap` (``spacing``, ``warning_cost``...).

    Attributes
    ----------
    view : FenceView
    frame : LocalFrame
        The view's.
    keep_out, warning : ndarray of shapely geometry
        The fences within reach, metres.
    keep_out_records : list of FenceRecord
        One per ``keep_out``.
    out_of_reach : int
        Keep-out fences and warning layers left out, farther than ``REACH_M``.
    corridors : list of Corridor
        Those routed in so far, first first.
    roadmap : Roadmap or None
        The last corridor's.
    added : int
        Waypoints the last route gained along its legs so that, flown, they keep the clearance.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> box = shapely.box(14.500, 35.900, 14.502, 35.902)
    >>> far = shapely.box(151.2, -33.9, 151.21, -33.89)  # Sydney, not in the corridor
    >>> fences = [FenceRecord("power/way/7", "keep_out", box), FenceRecord("x", "keep_out", far)]
    >>> planner = CorridorPlanner(fences, (14.497, 35.901), (14.505, 35.901), clearance=20.0)
    >>> route, lonlat = planner.route()
    >>> round(route.length_m), route.min_clearance_m >= 20, planner.corridors[0].fences.tolist()
    (783, True, [0])
    """

    def __init__(
        self, records, start, goal, clearance=20.0, half_width=None, view=None, **roadmap_options
    ):
        self.start = (float(start[0]), float(start[1]))
        self.goal = (float(goal[0]), float(goal[1]))
        if view is None:
            view = FenceView(records, LocalFrame.around_coords([self.start, self.goal]), clearance)
        self.view = view
        self.clearance = view.clearance
        self.options = roadmap_options
        self.frame = view.frame
        self.out_of_reach = view.out_of_reach
        self.keep_out_records = view.keep_out_records
        self.keep_out, self.warning = view.keep_out, view.warning
        self.tree, self.wtree = view.tree, view.wtree
        self.start_xy = view.to_xy(self.start)
        self.goal_xy = view.to_xy(self.goal)
        self.line = shapely.LineString([self.start_xy, self.goal_xy])
        distance = float(np.hypot(*(self.goal_xy - self.start_xy)))
        self.half_width = float(
            half_width if half_width else 0.25 * distance + 20.0 * (self.clearance + EPS_CLEAR)
        )
        self.corridors = []
        self.roadmap = None
        self.added = 0

    def corridor(self, half_width):
        """The fences within ``half_width`` metres of the segment from start to goal.

        Returns
        -------
        Corridor
            Numbered after those already routed in.
        """
        near = dict(predicate="dwithin", distance=float(half_width))
        fences = np.sort(self.tree.query(self.line, **near))
        warnings = np.sort(self.wtree.query(self.line, **near))
        number = len(self.corridors) + 1
        return Corridor(number, float(half_width), fences, warnings, len(self.keep_out))

    def _roadmap(self, c):
        ends = np.array([self.start_xy, self.goal_xy])
        return Roadmap(
            list(self.keep_out[c.fences]),
            list(self.warning[c.warnings]),
            clearance=self.clearance,
            names=[fence_label(self.keep_out_records[i]) for i in c.fences],
            bounds=(*ends.min(axis=0), *ends.max(axis=0)),
            **self.options,
        )

    def too_close(self, xy, ce=None):
        """Keep-out fences (indices into ``keep_out``) closer than the clearance (plus
        ``EPS_CLEAR``, or ``ce``) to the path ``xy``, metres."""
        ce = self.clearance + EPS_CLEAR if ce is None else ce
        legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
        return np.unique(self.tree.query(legs, predicate="dwithin", distance=ce)[1])

    def route(self, smooth=True, progress=None) -> tuple[Route, np.ndarray]:
        """The cheapest route found, clear of every keep-out fence within reach.

        Parameters
        ----------
        smooth : bool
            Pull the path taut by line of sight.
        progress : callable, optional
            Called with each :class:`Corridor` before its roadmap is built.

        Returns
        -------
        route : Route
            Metres of ``frame``, its legs split where ArduPilot, flying them as straight
            lon/lat lines, would come closer to a fence than the clearance
            (:meth:`FenceView.flown`); its clearance and warning metres are those of the legs
            as flown, measured against every fence within reach.
        lonlat : ndarray, shape (n, 2)
            Its vertices, lon, lat (start and goal exactly as given).

        Raises
        ------
        NoRoute
            Start or goal too close to a keep-out fence, or enclosed (the message names the
            fences).
        """
        half_width = self.half_width
        while True:
            c = self.corridor(half_width)
            self.corridors.append(c)
            if progress is not None:
                progress(c)
            self.roadmap = self._roadmap(c)
            r = self.roadmap.route(self.start_xy, self.goal_xy, smooth)
            outside = np.setdiff1d(self.too_close(r.xy, self.roadmap.ce), c.fences)
            c.outside = int(outside.size)
            if not outside.size:
                break
            # wider, and at least wide enough to take in the fences the route came too close to
            far = float(shapely.distance(self.line, self.keep_out[outside]).max())
            half_width = max(2.0 * half_width, far + 1.0)
        lon, lat = self.frame.to_wgs84(r.xy[:, 0], r.xy[:, 1])
        lonlat = np.column_stack([lon, lat])
        lonlat[0] = self.start  # the exact positions asked for, not a round trip
        lonlat[-1] = self.goal
        if len(lonlat) < 2:
            return r, lonlat
        xy, lonlat, legs = self.view.flown(r.xy, lonlat)
        self.added = len(xy) - len(r.xy)
        return self._measured(dataclasses.replace(r, xy=xy), legs), lonlat

    def _measured(self, r, legs):
        """``r`` with its clearance and warning metres, its ``legs`` as flown (lon/lat
        readings) against every fence within reach."""
        clearance = float(flown_distance(self.tree, legs).min())
        warn = 0.0
        i, j = self.wtree.query(legs, predicate="intersects")
        if i.size:
            warn = float(shapely.length(shapely.intersection(legs[i], self.warning[j])).sum())
        return dataclasses.replace(r, min_clearance_m=clearance, warning_m=warn)
