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

Everything is in metres of one local frame centred between start and goal; fences farther
than ``REACH_M`` from its centre, where the frame no longer serves, are out of reach.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.planner import fence_label
from alphafence.route.roadmap import EPS_CLEAR, Roadmap, Route

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
    """WGS84 geometries in the metres of ``frame``, a chunk at a time, and which are in reach.

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
        part = frame.geom_to_local(geoms[i : i + chunk])
        local[i : i + chunk] = part
        xy, index = shapely.get_coordinates(part, return_index=True)
        far = ~(np.hypot(xy[:, 0], xy[:, 1]) <= reach)  # NaN is far too
        good = ~shapely.is_empty(part)
        good[np.unique(index[far])] = False
        ok[i : i + chunk] = good
    return local, ok


class CorridorPlanner:
    """Routes from ``start`` to ``goal`` over only the fences in a corridor around them,
    widening it while the route comes too close to a fence left out.

    Parameters
    ----------
    records : list of FenceRecord
        Keep-out fences are avoided, warning layers cost more; keep-in fences are ignored.
    start, goal : tuple of float
        ``(lon, lat)``.
    clearance : float
        Least distance from any keep-out fence, metres.
    half_width : float, optional
        The first corridor's: fences within this many metres of the segment from start to
        goal. Default a quarter of the distance plus twenty times the clearance.
    **roadmap_options
        Passed to every :class:`Roadmap` (``spacing``, ``warning_cost``...).

    Attributes
    ----------
    frame : LocalFrame
        Centred between start and goal.
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

    Examples
    --------
    >>> import shapely
    >>> from alphafence.formats.fence_geojson import FenceRecord
    >>> box = shapely.box(14.500, 35.900, 14.502, 35.902)
    >>> far = shapely.box(151.2, -33.9, 151.21, -33.89)  # Sydney, not in the corridor
    >>> fences = [FenceRecord("power/way/7", "keep_out", box), FenceRecord("x", "keep_out", far)]
    >>> planner = CorridorPlanner(fences, (14.497, 35.901), (14.505, 35.901), clearance=20.0)
    >>> route, lonlat = planner.route()
    >>> round(route.length_m), route.min_clearance_m >= 20, planner.corridors[0].fences.tolist()
    (783, True, [0])
    """

    def __init__(self, records, start, goal, clearance=20.0, half_width=None, **roadmap_options):
        self.start = (float(start[0]), float(start[1]))
        self.goal = (float(goal[0]), float(goal[1]))
        self.clearance = float(clearance)
        self.options = roadmap_options
        self.frame = LocalFrame.around_coords([self.start, self.goal])
        ko = [r for r in records if r.kind == "keep_out"]
        wa = [r for r in records if r.kind == "warning"]
        ko_local, ko_ok = project(self.frame, [r.geometry for r in ko])
        wa_local, wa_ok = project(self.frame, [r.geometry for r in wa])
        self.out_of_reach = int((~ko_ok).sum() + (~wa_ok).sum())
        self.keep_out_records = [ko[i] for i in np.flatnonzero(ko_ok)]
        self.keep_out = shapely.make_valid(ko_local[ko_ok])
        self.warning = wa_local[wa_ok]
        self.tree = shapely.STRtree(self.keep_out)
        self.wtree = shapely.STRtree(self.warning)
        self.start_xy = self._xy(self.start)
        self.goal_xy = self._xy(self.goal)
        self.line = shapely.LineString([self.start_xy, self.goal_xy])
        distance = float(np.hypot(*(self.goal_xy - self.start_xy)))
        self.half_width = float(
            half_width if half_width else 0.25 * distance + 20.0 * (self.clearance + EPS_CLEAR)
        )
        self.corridors = []
        self.roadmap = None

    def _xy(self, lonlat):
        x, y = self.frame.to_local(lonlat[0], lonlat[1])
        return np.array([float(x), float(y)])

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
            Metres of ``frame``; its clearance and warning metres are measured against
            every fence within reach.
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
        r = self._measured(r)
        lon, lat = self.frame.to_wgs84(r.xy[:, 0], r.xy[:, 1])
        lonlat = np.column_stack([lon, lat])
        lonlat[0] = self.start  # the exact positions asked for, not a round trip
        lonlat[-1] = self.goal
        return r, lonlat

    def _measured(self, r):
        """``r`` with its clearance and warning metres against every fence within reach."""
        xy = r.xy
        if len(xy) < 2:
            return r
        legs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
        clearance = r.min_clearance_m
        if len(self.keep_out):
            _, d = self.tree.query_nearest(legs, return_distance=True, all_matches=False)
            clearance = float(d.min())
        warn = 0.0
        i, j = self.wtree.query(legs, predicate="intersects")
        if i.size:
            warn = float(shapely.length(shapely.intersection(legs[i], self.warning[j])).sum())
        return dataclasses.replace(r, min_clearance_m=clearance, warning_m=warn)
