"""A reusable roadmap around keep-out fences: Voronoi edges clear by a margin, A*, smoothing.

Everything here is in metres of one local frame (``alphafence.geo.frame.LocalFrame``); the caller converts.

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

import heapq
import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import QhullError, Voronoi, cKDTree

from alphafence.errors import RoutingError

# The planner keeps this much more than the asked clearance, so that an independent exact
# check (shapely.distance) never finds a path a rounding error closer than the clearance.
EPS_CLEAR = 0.05


class NoRoute(RoutingError):
    """No route: ``str(err)`` is a one-line reason naming what blocks it."""


@dataclass
class Route:
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


class Roadmap:
    """Voronoi roadmap clear of ``keep_out`` (shapely polygons in metres) by ``clearance``."""

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
    def clear(self, a, b):
        """Boolean per segment a[i]-b[i]: at least the clearance from every keep-out fence."""
        segs = _segments(a, b)
        ok = np.ones(len(segs), bool)
        if self.tree is not None and len(segs):
            hit = self.tree.query(segs, predicate="dwithin", distance=self.ce)
            ok[hit[0]] = False
        return ok

    def point_clear(self, xy):
        pts = shapely.points(np.asarray(xy, float).reshape(-1, 2))
        ok = np.ones(len(pts), bool)
        if self.tree is not None:
            hit = self.tree.query(pts, predicate="dwithin", distance=self.ce)
            ok[hit[0]] = False
        return ok

    def warning_length(self, a, b):
        segs = _segments(a, b)
        out = np.zeros(len(segs))
        if self.wtree is not None and len(segs):
            i, j = self.wtree.query(segs, predicate="intersects")
            if i.size:
                np.add.at(out, i, shapely.length(shapely.intersection(segs[i], self.warning[j])))
        return out

    def clearance_of(self, a, b):
        """Exact distance of each segment to the nearest keep-out fence."""
        segs = _segments(a, b)
        d = np.full(len(segs), np.inf)
        if self.tree is not None and len(segs):
            (i, _), dist = self.tree.query_nearest(segs, return_distance=True, all_matches=False)
            d[i] = dist
        return d

    def cost(self, a, b):
        a = np.asarray(a, float).reshape(-1, 2)
        b = np.asarray(b, float).reshape(-1, 2)
        length = np.hypot(*(b - a).T)
        d = self.clearance_of(a, b)
        near = np.clip(1.0 - (d - self.ce) / self.proximity_range, 0.0, 1.0)
        return length * (
            1.0 + self.proximity_cost * near
        ) + self.warning_cost * self.warning_length(a, b)

    # -- build -----------------------------------------------------------------
    def _build(self, bounds):
        s = self.spacing
        if self.keep_out.size:
            fb = np.asarray(shapely.total_bounds(self.keep_out), float)
        else:
            fb = np.array([-1.0, -1.0, 1.0, 1.0])
        if bounds is not None:
            b = np.asarray(bounds, float)
            fb = np.array([min(fb[0], b[0]), min(fb[1], b[1]), max(fb[2], b[2]), max(fb[3], b[3])])
        pad = max(4.0 * self.ce, 200.0)
        self.bounds = fb + np.array([-pad, -pad, pad, pad])
        x0, y0, x1, y1 = self.bounds
        frame = shapely.segmentize(shapely.box(x0, y0, x1, y1).exterior, max(4.0 * s, pad / 4))
        pts = [shapely.get_coordinates(frame)]
        if self.keep_out.size:
            rings = shapely.boundary(self.keep_out)
            pts.append(shapely.get_coordinates(shapely.segmentize(rings, s)))
        if self.warning.size:  # so that the roadmap also has ways around warning layers
            rings = shapely.boundary(self.warning)
            pts.append(shapely.get_coordinates(shapely.segmentize(rings, 2.0 * s)))
        pts = np.unique(np.round(np.concatenate(pts), 6), axis=0)
        self.samples = pts
        try:
            vor = Voronoi(pts)
        except QhullError as exc:  # degenerate input, e.g. all samples collinear
            raise ValueError(f"cannot build the roadmap ({exc})") from None
        rv = np.asarray(vor.ridge_vertices)
        rv = rv[(rv >= 0).all(axis=1)]
        rv = np.sort(rv, axis=1)
        rv = np.unique(rv, axis=0)
        V = vor.vertices
        inside = (V[:, 0] >= x0) & (V[:, 0] <= x1) & (V[:, 1] >= y0) & (V[:, 1] <= y1)
        rv = rv[inside[rv].all(axis=1)]
        rv = rv[rv[:, 0] != rv[:, 1]]
        ok = self.clear(V[rv[:, 0]], V[rv[:, 1]])
        rv = rv[ok]
        used, inv = np.unique(rv, return_inverse=True)
        V = V[used]
        edges = inv.reshape(-1, 2)
        V, edges = self._add_rings(V, edges)
        self.vertices = V
        self.edges = edges
        w = self.cost(self.vertices[edges[:, 0]], self.vertices[edges[:, 1]])
        self.edge_cost = w
        n = len(self.vertices)
        src = np.concatenate([edges[:, 0], edges[:, 1]])
        dst = np.concatenate([edges[:, 1], edges[:, 0]])
        ww = np.concatenate([w, w])
        order = np.argsort(src, kind="stable")
        self._indptr = np.searchsorted(src[order], np.arange(n + 1)).tolist()
        self._nbr = dst[order].tolist()
        self._w = ww[order].tolist()
        self.kdtree = cKDTree(self.vertices) if n else None

    def _add_rings(self, V, edges, k=4):
        """Hugging ways: rings just outside the clearance of every keep-out fence and outside
        every warning layer, joined to the Voronoi edges. Without them the only ways round a
        fence in open space run down the far-away medial axis, which misprices them."""
        polys = [g for g in (*self.keep_out, *self.warning)]
        if not polys:
            return V, edges
        r = np.concatenate(
            [np.full(len(self.keep_out), 1.25 * self.ce + 1.0), np.full(len(self.warning), 1.0)]
        )
        rings = shapely.boundary(
            shapely.simplify(shapely.buffer(np.array(polys, dtype=object), r, quad_segs=2), 0.5)
        )
        rings = shapely.segmentize(rings, 4.0 * self.spacing)
        new_v, new_e = [], []
        base = len(V)
        for line in shapely.get_parts(rings):
            c = np.asarray(line.coords)
            if len(c) < 3:
                continue
            c = c[:-1] if np.allclose(c[0], c[-1]) else c
            m = len(c)
            idx = base + np.arange(m)
            new_v.append(c)
            new_e.append(np.column_stack([idx, np.roll(idx, -1)]))
            base += m
        if not new_v:
            return V, edges
        R = np.concatenate(new_v)
        RE = np.concatenate(new_e)
        RE = RE[self.clear(np.vstack([V, R])[RE[:, 0]], np.vstack([V, R])[RE[:, 1]])]
        allv = np.vstack([V, R])
        links = np.zeros((0, 2), int)
        if len(V):  # each ring vertex to its nearest visible Voronoi vertices
            kk = min(k, len(V))
            _, nn = cKDTree(V).query(R, k=kk)
            src = np.repeat(np.arange(len(V), len(allv)), kk)
            dst = np.asarray(nn).reshape(-1)
            ok = self.clear(allv[src], allv[dst])
            links = np.column_stack([src[ok], dst[ok]])
        E = np.vstack([edges, RE, links])
        E = np.unique(np.sort(E, axis=1), axis=0)
        E = E[E[:, 0] != E[:, 1]]
        return allv, E

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
        path, expanded = self._astar(src, dst, g, direct) if direct or (src and dst) else (None, 0)
        if path is None:
            raise NoRoute(self._diagnose(s, g, bool(src), bool(dst)))
        raw = np.vstack([s, self.vertices[path], g]) if path else np.array([s, g])
        out = self._smooth(raw) if smooth else raw
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

    def _astar(self, src, dst, goal, direct=None):
        V = self.vertices
        h = np.hypot(V[:, 0] - goal[0], V[:, 1] - goal[1]).tolist()
        ip, nbr, w = self._indptr, self._nbr, self._w
        n = len(V)
        INF = math.inf
        dist = [INF] * n
        parent = [-1] * n
        closed = bytearray(n)
        heap = []
        for v, c in src:
            if c < dist[v]:
                dist[v] = c
                heapq.heappush(heap, (c + h[v], c, v, -1))
        GOAL = -2
        if direct is not None:
            heap.append((direct, direct, GOAL, -1))
            heapq.heapify(heap)
        expanded = 0
        push, pop = heapq.heappush, heapq.heappop
        while heap:
            f, c, v, p = pop(heap)
            if v == GOAL:
                if p == -1:
                    return [], expanded
                path = [p]
                while parent[path[-1]] != -1:
                    path.append(parent[path[-1]])
                return path[::-1], expanded
            if closed[v] or c > dist[v]:
                continue
            closed[v] = 1
            parent[v] = p
            expanded += 1
            last = dst.get(v)
            if last is not None:
                push(heap, (c + last, c + last, GOAL, v))
            for k in range(ip[v], ip[v + 1]):
                m = nbr[k]
                if closed[m]:
                    continue
                nc = c + w[k]
                if nc < dist[m]:
                    dist[m] = nc
                    push(heap, (nc + h[m], nc, m, v))
        return None, expanded

    # -- smoothing -------------------------------------------------------------
    def _shortcut(self, P):
        """Greedy: from each kept vertex jump to the farthest one in clear line of sight that
        does not add warning-layer metres."""
        n = len(P)
        if n <= 2:
            return P
        wl = np.concatenate([[0.0], np.cumsum(self.warning_length(P[:-1], P[1:]))])
        keep = [0]
        i = 0
        while i < n - 1:
            rest = n - 1 - i
            if rest <= 192:
                cand = np.arange(i + 2, n)
            else:
                near = np.arange(i + 2, i + 130)
                far = np.unique(np.linspace(i + 130, n - 1, 64).astype(int))
                cand = np.concatenate([near, far])
            j = i + 1
            if cand.size:
                a = np.repeat(P[i : i + 1], len(cand), axis=0)
                ok = self.clear(a, P[cand])
                if self.wtree is not None and ok.any():
                    c2 = cand[ok]
                    extra = self.warning_length(a[: len(c2)], P[c2]) - (wl[c2] - wl[i])
                    ok[np.flatnonzero(ok)[extra > 1e-6]] = False
                if ok.any():
                    j = int(cand[ok].max())
            keep.append(j)
            i = j
        return P[keep]

    def _cut(self, P):
        """Cut every corner as deep as line of sight allows: vertex i becomes two points on its
        legs, at the largest fraction u <= 1/2 of each leg whose chord is clear (and adds no
        warning-layer metres). Each leg is shared by at most two cuts of at most half, so the
        rest of the path is unchanged and stays clear."""
        n = len(P)
        if n <= 2:
            return P
        v = P[1:-1]
        da = P[:-2] - v
        db = P[2:] - v
        lo = np.zeros(n - 2)
        hi = np.full(n - 2, 0.5)
        warn = self.wtree is not None
        if warn:
            wa = self.warning_length(P[:-2], v)
            wb = self.warning_length(v, P[2:])
        for it in range(9):
            t = hi if it == 0 else 0.5 * (lo + hi)
            pa = v + t[:, None] * da
            pb = v + t[:, None] * db
            ok = self.clear(pa, pb)
            if warn:  # a chord may enter warning layers only where both legs were inside
                ok &= self.warning_length(pa, pb) <= np.where(wa + wb > 0, wa + wb, 0) + 1e-6
            lo = np.where(ok, t, lo)
            hi = np.where(ok, hi, t)
            if it == 0 and ok.all():
                break
        # no cuts shorter than half the sample spacing: they would only add waypoints
        short = np.minimum(np.hypot(*da.T), np.hypot(*db.T))
        lo[lo * short < 0.5 * self.spacing] = 0.0
        out = [P[:1]]
        for k in range(n - 2):
            if lo[k] > 0.0:
                out.append(np.array([v[k] + lo[k] * da[k], v[k] + lo[k] * db[k]]))
            else:
                out.append(v[k : k + 1])
        out.append(P[-1:])
        return np.concatenate(out)

    def _smooth(self, P, rounds=12):
        P = self._shortcut(P)
        length = np.hypot(*np.diff(P, axis=0).T).sum()
        for _ in range(rounds):
            if len(P) <= 2:
                break
            P = self._shortcut(self._cut(P))
            new = np.hypot(*np.diff(P, axis=0).T).sum()
            if length - new < 1e-3 * self.spacing:
                break
            length = new
        # drop (near-)duplicate points
        keep = np.concatenate([[True], np.hypot(*np.diff(P, axis=0).T) > 1e-6])
        keep[-1] = True
        return P[keep]

    # -- diagnosis -------------------------------------------------------------
    def _diagnose(self, s, g, s_linked, g_linked):
        """A one-line reason: which of start and goal is enclosed, and by which fences."""
        x0, y0, x1, y1 = self.bounds
        x0, x1 = min(x0, s[0], g[0]) - 1, max(x1, s[0], g[0]) + 1
        y0, y1 = min(y0, s[1], g[1]) - 1, max(y1, s[1], g[1]) + 1
        blocked = shapely.union_all(shapely.buffer(self.keep_out, self.ce, quad_segs=16))
        free = shapely.difference(shapely.box(x0, y0, x1, y1), blocked)
        parts = shapely.get_parts(free)
        ps, pg = shapely.points(s), shapely.points(g)
        cs = next((p for p in parts if p.intersects(ps)), None)
        cg = next((p for p in parts if p.intersects(pg)), None)
        if cs is not None and cg is not None and cs.equals(cg):
            return (
                "no route found on the roadmap although start and goal share free space "
                f"(gaps barely wider than twice the clearance of {self.clearance:g} m); "
                "try a smaller --clearance"
            )
        # the enclosed end is the one whose free pocket is bounded (smaller)
        if cs is None or cg is None:
            label, pocket = ("start", cs) if cg is None else ("goal", cg)
        elif cs.area <= cg.area:
            label, pocket = "start", cs
        else:
            label, pocket = "goal", cg
        if pocket is None:
            return f"the {label} is enclosed by keep-out fences"
        ring = shapely.LinearRing(pocket.exterior.coords)
        near = self.tree.query(ring, predicate="dwithin", distance=self.ce * 1.05 + 0.5)
        names = sorted({self.names[int(k)] for k in np.atleast_1d(near)})
        shown = ", ".join(names[:6]) + (f" (+{len(names) - 6} more)" if len(names) > 6 else "")
        return (
            f"the {label} is enclosed by keep-out fence{'s' if len(names) != 1 else ''} {shown}: "
            f"no gap of twice the clearance ({2 * self.clearance:g} m) leads out"
        )
