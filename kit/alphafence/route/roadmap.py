"""A reusable roadmap around keep-out fences: Voronoi edges clear by a margin, A*, smoothing.

Everything here is in metres of one local frame (``alphafence.geo.frame.LocalFrame``); the
caller converts. This module builds the graph and answers queries; the search is in
``route.search`` and the smoothing in ``route.smooth``.

* **Roadmap**: the Voronoi diagram (``scipy.spatial.Voronoi``) of points sampled along the
  keep-out boundaries runs down the middle of every gap between fences. Its finite edges are
  kept where they stay at least ``clearance`` from every keep-out fence: one vectorised
  STRtree ``dwithin`` query against the *exact* fence polygons (no buffer approximation).
* **Cost**: edge length, weighted up near fences (within ``proximity_range`` of the clearance
  distance) and for every metre inside a warning layer, so routes prefer open air.
* **Query** (:meth:`Roadmap.route`): start and goal join the roadmap through clear segments to
  their nearest visible roadmap vertices; A* with the Euclidean heuristic (admissible: every
  edge costs at least its length); then the path is pulled taut by line of sight (shortcuts,
  then vertex pulling), never cutting deeper into a warning layer than the A* path did.

The roadmap is built once per fence set; each :meth:`Roadmap.route` call is independent, so a
monitor can re-route in flight.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from alphafence.errors import RoutingError
from alphafence.route.graph import add_rings, adjacency_lists, voronoi_edges
from alphafence.route.search import astar, diagnose
from alphafence.route.smooth import smooth_path

# The planner keeps this much more than the asked clearance, so that an independent exact
# check (shapely.distance) never finds a path a rounding error closer than the clearance.
EPS_CLEAR = 0.05
# segments checked a call (a few tenths of a second at most): Ctrl-C is heard between calls
CHUNK = 16_384


class NoRoute(RoutingError):
    """No route: ``str(err)`` is a one-line reason naming what blocks it."""


@dataclass
class Route:
    """A route found on a :class:`Roadmap`, in metres of its frame.

    Attributes
    ----------
    xy : ndarray, shape (n, 2)
        The vertices, start first, goal last.
    length_m : float
        Its length.
    min_clearance_m : float
        Exact distance to the nearest keep-out fence (inf when there is none).
    warning_m : float
        Metres flown inside warning layers.
    raw_xy : ndarray, shape (m, 2)
        The A* path before smoothing.
    expanded : int
        A* vertices expanded.
    """

    xy: np.ndarray  # (n, 2) metres, start first, goal last
    length_m: float
    min_clearance_m: float  # exact distance to the nearest keep-out fence (inf if none)
    warning_m: float  # metres flown inside warning layers
    raw_xy: np.ndarray = field(repr=False, default=None)  # the A* path before smoothing
    expanded: int = 0  # A* nodes expanded


def _segments(a, b):
    a = np.asarray(a, float).reshape(-1, 2)
    b = np.asarray(b, float).reshape(-1, 2)
    return shapely.linestrings(np.stack([a, b], axis=1))


def _by_chunks(fn):
    """``fn(self, a, b)`` over at most ``CHUNK`` segments a call, so that no GEOS call runs
    long enough to keep Ctrl-C waiting."""

    @functools.wraps(fn)
    def chunked(self, a, b, *args, **kwargs):
        a = np.asarray(a, float).reshape(-1, 2)
        b = np.asarray(b, float).reshape(-1, 2)
        if len(a) <= CHUNK:
            return fn(self, a, b, *args, **kwargs)
        parts = [
            fn(self, a[i : i + CHUNK], b[i : i + CHUNK], *args, **kwargs)
            for i in range(0, len(a), CHUNK)
        ]
        return np.concatenate(parts)

    return chunked


class Roadmap:
    """Voronoi roadmap clear of ``keep_out`` (shapely polygons in metres) by ``clearance``.

    Parameters
    ----------
    keep_out : sequence of shapely geometry
        Keep-out fences, metres; empty ones are ignored.
    warning : sequence of shapely geometry
        Warning layers: flying through them costs ``warning_cost`` more a metre.
    clearance : float
        Least distance from any keep-out fence, metres (``EPS_CLEAR`` is kept on top).
    names : list of str, optional
        One per keep-out fence, for the reason a route is impossible.
    spacing : float, optional
        Sampling distance along fence boundaries (default: half the clearance, 2 to 20 m).
    bounds : tuple, optional
        ``(x0, y0, x1, y1)`` the roadmap must also cover (e.g. start and goal).
    proximity_cost : float
        Extra cost a metre right at the clearance distance, fading out over
        ``proximity_range`` metres.
    proximity_range : float, optional
        Default: twice the clearance, at least 25 m.
    warning_cost : float
        Extra cost a metre inside a warning layer.

    Examples
    --------
    >>> import shapely
    >>> roadmap = Roadmap([shapely.box(-50, -50, 50, 50)], clearance=20)
    >>> route = roadmap.route((-200, 0), (200, 0))
    >>> round(route.length_m), route.min_clearance_m >= 20
    (432, True)
    """

    def __init__(
        self,
        keep_out,
        warning=(),
        clearance: float = 20.0,
        names=None,
        spacing: float | None = None,
        bounds=None,
        proximity_cost: float = 0.5,
        proximity_range: float | None = None,
        warning_cost: float = 1.0,
    ):
        if clearance < 0 or not math.isfinite(clearance):
            raise ValueError("clearance must be a non-negative number of metres")
        self.clearance = float(clearance)
        self.ce = self.clearance + EPS_CLEAR
        self.keep_out = np.array(
            [shapely.make_valid(g) for g in keep_out if g is not None and not g.is_empty],
            dtype=object,
        )
        self.names = list(names) if names is not None else [f"#{i}" for i in range(len(keep_out))]
        self.warning = np.array(
            [g for g in warning if g is not None and not g.is_empty], dtype=object
        )
        self.spacing = (
            float(spacing) if spacing else float(np.clip(self.clearance / 2.0, 2.0, 20.0))
        )
        self.proximity_cost = float(proximity_cost)
        self.proximity_range = float(proximity_range or max(2.0 * self.clearance, 25.0))
        self.warning_cost = float(warning_cost)
        self.tree = shapely.STRtree(self.keep_out) if self.keep_out.size else None
        self.wtree = shapely.STRtree(self.warning) if self.warning.size else None
        shapely.prepare(self.keep_out)
        self._build(bounds)

    # -- geometry predicates (vectorised) -------------------------------------
    @_by_chunks
    def clear(self, a, b):
        """Boolean per segment a[i]-b[i]: at least the clearance from every keep-out fence."""
        segs = _segments(a, b)
        ok = np.ones(len(segs), bool)
        if self.tree is not None and len(segs):
            hit = self.tree.query(segs, predicate="dwithin", distance=self.ce)
            ok[hit[0]] = False
        return ok

    def point_clear(self, xy):
        """Boolean per point: at least the clearance from every keep-out fence.

        Examples
        --------
        >>> import shapely
        >>> Roadmap([shapely.box(-50, -50, 50, 50)], clearance=20).point_clear([(0, 69), (0, 71)])
        array([False,  True])
        """
        pts = shapely.points(np.asarray(xy, float).reshape(-1, 2))
        ok = np.ones(len(pts), bool)
        if self.tree is not None:
            hit = self.tree.query(pts, predicate="dwithin", distance=self.ce)
            ok[hit[0]] = False
        return ok

    @_by_chunks
    def warning_length(self, a, b):
        """Metres of each segment a[i]-b[i] inside warning layers.

        Examples
        --------
        >>> import shapely
        >>> box = shapely.box(-50, -50, 50, 50)
        >>> Roadmap([box], [box.buffer(30, join_style="mitre")]).warning_length((-200, 0), (200, 0))
        array([160.])
        """
        segs = _segments(a, b)
        out = np.zeros(len(segs))
        if self.wtree is not None and len(segs):
            i, j = self.wtree.query(segs, predicate="intersects")
            if i.size:
                np.add.at(out, i, shapely.length(shapely.intersection(segs[i], self.warning[j])))
        return out

    @_by_chunks
    def clearance_of(self, a, b, max_distance=None):
        """Exact distance of each segment to the nearest keep-out fence (inf when there is
        none, or none within ``max_distance``)."""
        segs = _segments(a, b)
        d = np.full(len(segs), np.inf)
        if self.tree is None or not len(segs):
            return d
        if max_distance is None:
            (i, _), dist = self.tree.query_nearest(segs, return_distance=True, all_matches=False)
            d[i] = dist
        else:  # the fences within reach, then their distances: a few times faster
            i, j = self.tree.query(segs, predicate="dwithin", distance=max_distance)
            np.minimum.at(d, i, shapely.distance(segs[i], self.keep_out[j]))
        return d

    def cost(self, a, b):
        """What flying each segment a[i]-b[i] costs: its length, weighted up near keep-out
        fences (``proximity_cost``), plus ``warning_cost`` a metre inside warning layers.

        Examples
        --------
        >>> import shapely
        >>> roadmap = Roadmap([shapely.box(-50, -50, 50, 50)], clearance=20)
        >>> roadmap.cost([(-200, 200), (-200, 100)], [(200, 200), (200, 100)])
        array([400.  , 450.25])
        """
        a = np.asarray(a, float).reshape(-1, 2)
        b = np.asarray(b, float).reshape(-1, 2)
        length = np.hypot(*(b - a).T)
        # only fences within the proximity range weigh: no search for any farther
        d = self.clearance_of(a, b, self.ce + self.proximity_range)
        near = np.clip(1.0 - (d - self.ce) / self.proximity_range, 0.0, 1.0)
        return length * (
            1.0 + self.proximity_cost * near
        ) + self.warning_cost * self.warning_length(a, b)

    # -- build -----------------------------------------------------------------
    def _build(self, bounds):
        self.bounds, self.samples, V, edges = voronoi_edges(self, bounds)
        V, edges = add_rings(self, V, edges)
        self.vertices = V
        self.edges = edges
        w = self.cost(self.vertices[edges[:, 0]], self.vertices[edges[:, 1]])
        self.edge_cost = w
        n = len(self.vertices)
        self._adjacency = adjacency_lists(n, edges, w)
        from scipy.spatial import cKDTree

        self.kdtree = cKDTree(self.vertices) if n else None

    # -- queries ---------------------------------------------------------------
    def _blocker(self, xy):
        """(index, inside) of the nearest keep-out fence to a point."""
        p = shapely.points(np.asarray(xy, float).reshape(1, 2))
        (_, j), _ = self.tree.query_nearest(p, return_distance=True, all_matches=False)
        k = int(j[0])
        return k, bool(self.keep_out[k].intersects(p[0]))

    def _check_end(self, xy, label):
        if self.point_clear(xy)[0]:
            return
        k, inside = self._blocker(xy)
        d = float(shapely.distance(self.keep_out[k], shapely.points(xy)))
        if inside:
            raise NoRoute(f"the {label} is inside keep-out fence {self.names[k]}")
        raise NoRoute(
            f"the {label} is {d:.1f} m from keep-out fence {self.names[k]}, "
            f"closer than the clearance of {self.clearance:g} m"
        )

    def _links(self, xy, want=6):
        """Clear links (vertex, cost) from a point to its nearest visible roadmap vertices."""
        n = len(self.vertices)
        if not n:
            return []
        for k in (24, 256, 4096, n):
            k = min(k, n)
            _, idx = self.kdtree.query(xy, k=k)
            idx = np.atleast_1d(idx)
            idx = idx[idx < n]
            ok = self.clear(np.repeat([xy], len(idx), axis=0), self.vertices[idx])
            good = idx[ok][:want]
            if good.size:
                c = self.cost(np.repeat([xy], len(good), axis=0), self.vertices[good])
                return list(zip(good.tolist(), c.tolist()))
            if k == n:
                break
        return []

    def route(self, start_xy, goal_xy, smooth: bool = True) -> Route:
        """The cheapest route from ``start_xy`` to ``goal_xy`` (metres), pulled taut.

        Straight when the straight line is clear and outside warning layers; otherwise start
        and goal join their nearest visible roadmap vertices, A* finds the cheapest path, and
        (with ``smooth``) line of sight shortens it.

        Raises
        ------
        NoRoute
            Start or goal closer to a keep-out fence than the clearance, or enclosed; the
            message names the fences.

        Examples
        --------
        >>> import shapely
        >>> roadmap = Roadmap([shapely.box(-50, -50, 50, 50)], clearance=20)
        >>> roadmap.route((-200, 0), (0, 0))
        Traceback (most recent call last):
        ...
        alphafence.route.roadmap.NoRoute: the goal is inside keep-out fence #0
        """
        s = np.asarray(start_xy, float).reshape(2)
        g = np.asarray(goal_xy, float).reshape(2)
        self._check_end(s, "start")
        self._check_end(g, "goal")
        direct = None
        if self.clear(s, g)[0]:
            if self.wtree is None or self.warning_length(s, g)[0] <= 0.0:
                raw = np.array([s, g])
                return self._finish(raw, raw, 0)
            direct = float(self.cost(s, g)[0])  # clear, but through a warning layer
        src = self._links(s)
        dst = dict(self._links(g))
        path, expanded = (
            astar(self.vertices, self._adjacency, src, dst, g, direct)
            if direct or (src and dst)
            else (None, 0)
        )
        if path is None:
            raise NoRoute(diagnose(self, s, g))
        raw = np.vstack([s, self.vertices[path], g]) if path else np.array([s, g])
        out = smooth_path(self, raw) if smooth else raw
        return self._finish(out, raw, expanded)

    def _finish(self, xy, raw, expanded):
        seg = np.diff(xy, axis=0)
        length = float(np.hypot(*seg.T).sum())
        if len(xy) > 1:
            clearance = float(self.clearance_of(xy[:-1], xy[1:]).min())
            warn = float(self.warning_length(xy[:-1], xy[1:]).sum())
        else:
            clearance, warn = math.inf, 0.0
        return Route(xy, length, clearance, warn, raw, expanded)
