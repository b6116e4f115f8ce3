"""The first fence along a straight track, from the fences' edges: no geometry built per check.

The monitor asks, for each position, which keep-out the vehicle meets first within its
look-ahead and how far along. Asking GEOS means intersecting the track with each candidate
fence (an overlay that builds a new geometry) and measuring to it. Here every fence's boundary
is kept as straight segments, grouped by fence, once (:class:`FenceEdges`); a check solves the
track against the candidates' segments in a few vectorised numpy operations: the parameter
``t`` along the track where it crosses each segment, the least per fence, the least of all.

The answer is GEOS's to within rounding (a micrometre): the track from ``(x, y)`` along the
unit vector ``u`` for ``L`` metres meets a fence at the least ``t`` in ``[0, L]`` at which it
touches the fence's boundary, or at 0 when it starts inside the fence.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

TOUCH = 1e-9  # relative slack: a track that grazes a vertex or ends on an edge still meets it
FEW = 256  # up to this many segments are solved one by one in Python (numpy's calls cost more)
SIFT = 8  # a fence with more segments than this has those far from the track left out first
ALL_FOUR = 0x01010101  # four true numpy bools read as one 32-bit word (either byte order)


class FenceEdges:
    """Every fence's boundary as straight segments, by fence.

    Parameters
    ----------
    local : numpy.ndarray of shapely geometries
        The fences (polygons or multipolygons), in metres.

    Attributes
    ----------
    indptr : numpy.ndarray of int
        The segments of fence ``k`` are ``indptr[k]:indptr[k + 1]``.
    rows : numpy.ndarray
        Each segment's ``(ax, ay, dx, dy, length)``: its start, its vector to its end and its
        length (``ax`` ... ``length`` are its columns).
    bounds : numpy.ndarray
        Each fence's ``(xmin, ymin, xmax, ymax)`` (NaN for an empty one).

    Examples
    --------
    >>> edges = FenceEdges(shapely.box([10.0, 30.0], -1.0, [20.0, 40.0], 1.0))
    >>> edges.first_hit(0.0, 0.0, 1.0, 0.0, 50.0, np.array([1, 0]))
    (0, 10.0)
    >>> edges.first_hit(0.0, 0.0, -1.0, 0.0, 50.0, np.array([0, 1])) is None
    True
    """

    def __init__(self, local):
        parts, owner = shapely.get_parts(shapely.boundary(local), return_index=True)
        coords, line = shapely.get_coordinates(parts, return_index=True)
        same = line[1:] == line[:-1]  # consecutive vertices of one ring make a segment
        a, b = coords[:-1][same], coords[1:][same]
        fence = owner[line[:-1][same]].astype(np.intp, copy=False)  # 32-bit numpy: int32
        order = np.argsort(fence, kind="stable")
        a, b, fence = a[order], b[order], fence[order]
        self.indptr = np.zeros(len(local) + 1, dtype=np.intp)
        np.cumsum(np.bincount(fence, minlength=len(local)), out=self.indptr[1:])
        d = b - a
        self.rows = np.column_stack([a, d, np.hypot(d[:, 0], d[:, 1])])  # ax, ay, dx, dy, n
        self.ax, self.ay, self.dx, self.dy, self.length = self.rows.T
        self.bounds = shapely.bounds(local)
        # each segment's box as (xmin, -xmax, ymin, -ymax): it overlaps a box (x0, x1, y0, y1)
        # where every column is <= (x1, -x0, y1, -y0); and what bounds any slack (_margin)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        self.boxes = np.column_stack([lo[:, 0], -hi[:, 0], lo[:, 1], -hi[:, 1]])
        self._first = self.indptr.tolist()  # as plain ints: a few fences cost less than numpy
        self._extent = float(np.abs(a).sum(axis=1).max()) if len(a) else 0.0
        self._longest = float(self.length.max()) if len(a) else 0.0

    def first_hit(self, x, y, ux, uy, length, cand, inside=(), lower=None):
        """The first of the fences ``cand`` met along the track from ``(x, y)`` in the unit
        direction ``(ux, uy)`` within ``length`` metres, and how far along:
        ``(index, metres)``, the lowest index among equals, or None when none is met.

        Parameters
        ----------
        x, y : float
            The track's start, in metres.
        ux, uy : float
            Its direction, a unit vector.
        length : float
            How far it goes.
        cand : numpy.ndarray of int
            The fences asked (indices into the fences the edges were made of).
        inside : collection of int
            Fences that hold the start (met at 0 m), as the caller already knows them.
        lower : numpy.ndarray of float, optional
            The fences' distances from the start, if known: those farther than ``length``
            are not looked at.
        """
        cand = np.asarray(cand, dtype=np.intp)
        reach = length * (1.0 + TOUCH) + TOUCH
        if lower is not None:
            cand = cand[lower <= reach]
        elif cand.size:
            ex, ey = x + ux * length, y + uy * length
            b = self.bounds[cand]
            near = (b[:, 0] <= max(x, ex) + reach * TOUCH) & (b[:, 2] >= min(x, ex) - reach * TOUCH)
            near &= (b[:, 1] <= max(y, ey) + reach * TOUCH) & (
                b[:, 3] >= min(y, ey) - reach * TOUCH
            )
            cand = cand[near]
        if not cand.size:
            return None
        indptr, first, ks = self.indptr, self._first, cand.tolist()
        if sum(first[k + 1] - first[k] for k in ks) <= FEW:
            best, best_k = math.inf, None
            box = None
            for k in ks:
                if k in inside:
                    t = 0.0
                else:
                    if box is None:
                        box = np.array(self.track_box(x, y, ux, uy, length))
                    t = self._along_few(x, y, ux, uy, length, first[k], first[k + 1], box)
                if t < best or (t == best and best_k is not None and k < best_k):
                    best, best_k = t, k
            return None if best_k is None else (best_k, best)
        if cand.size == 1:  # most often: one fence within reach, its segments a slice
            k = int(cand[0])
            seg = slice(indptr[k], indptr[k + 1])
            first = np.zeros(1, dtype=np.intp)
        else:
            starts, counts = indptr[cand], indptr[cand + 1] - indptr[cand]
            first = np.cumsum(counts) - counts
            seg = np.repeat(starts - first, counts) + np.arange(int(counts.sum()))
        t = self._along(x, y, ux, uy, length, seg)
        per = np.minimum.reduceat(t, first) if t.size else np.full(cand.size, np.inf)
        if len(inside):
            per[np.isin(cand, np.fromiter(inside, dtype=np.intp))] = 0.0
        best = float(per.min())
        if best == np.inf:
            return None
        return int(cand[per == best].min()), best

    def track_box(self, x, y, ux, uy, length):
        """The track's box widened by :meth:`_margin`, as ``(xmax, -xmin, ymax, -ymin)``: a
        segment can only meet the track where its box overlaps this one (``_along_few``)."""
        ex, ey, m = x + ux * length, y + uy * length, self._margin(x, y, length)
        return (max(x, ex) + m, m - min(x, ex), max(y, ey) + m, m - min(y, ey))

    def _margin(self, x, y, length):
        """How far beyond the track's box a segment that meets it may lie: twice the most
        slack any segment has here (its start is at most ``_extent`` from the origin, so
        ``|px| + |py|`` is at most ``_extent + |x| + |y|``), and what a segment parallel to the
        track within :data:`TOUCH` may drift off its line; doubled again for rounding."""
        slack = TOUCH * (self._extent + abs(x) + abs(y) + self._longest + length)
        return 4.0 * slack + 2.0 * TOUCH * self._longest + 1e-9

    def _along_few(self, x, y, ux, uy, length, a, b, box=None):
        """:meth:`_along`'s least, for the segments ``a:b``, in plain floats (the same
        arithmetic, operation for operation); with ``box``
        (:meth:`track_box`), only the segments whose boxes overlap it: the others cannot meet
        the track, so the least is the same."""
        rows = self.rows[a:b]
        if box is not None and b - a > SIFT:  # all four of a row <= box: its bools as one word
            rows = rows[(self.boxes[a:b] <= box).view(np.uint32).ravel() == ALL_FOUR]
        best = math.inf
        for ax, ay, dx, dy, n in rows.tolist():
            px, py = ax - x, ay - y
            den = ux * dy - uy * dx
            slack = TOUCH * (abs(px) + abs(py) + n + length)
            if abs(den) > TOUCH * n:  # the lines cross
                t = (px * dy - py * dx) / den
                s = (px * uy - py * ux) / den
                ds = slack / n
                if -ds <= s <= 1.0 + ds and -slack <= t <= length + slack and t < best:
                    best = t
            elif abs(px * uy - py * ux) <= slack:  # along the track's line
                t0 = px * ux + py * uy
                t1 = t0 + (dx * ux + dy * uy)
                lo, hi = min(t0, t1), max(t0, t1)
                if hi >= -slack and lo <= length + slack and lo < best:
                    best = lo
        return max(best, 0.0)

    def _along(self, x, y, ux, uy, length, seg):
        """For each segment of ``seg``: how far along the track it is met (inf: it is not).

        A segment whose line crosses the track's (at more than :data:`TOUCH` radians) is met
        where they cross, if that is on both; one (nearly) parallel to it, where its nearer
        end lies, if it lies on the track's line."""
        px, py = self.ax[seg] - x, self.ay[seg] - y
        dx, dy, n = self.dx[seg], self.dy[seg], self.length[seg]
        den = ux * dy - uy * dx  # cross(u, d) = n sin(angle between them)
        slack = TOUCH * (np.abs(px) + np.abs(py) + n + length)  # metres
        cross = np.abs(den) > TOUCH * n
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = (px * dy - py * dx) / den  # where the track's line meets the segment's
            s = (px * uy - py * ux) / den  # and how far along the segment (0..1)
            ds = slack / n  # the slack in s
        ok = cross & (s >= -ds) & (s <= 1.0 + ds) & (t >= -slack) & (t <= length + slack)
        t = np.where(ok, t, np.inf)
        if not cross.all():
            t0 = px * ux + py * uy
            t1 = t0 + (dx * ux + dy * uy)
            lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)
            on = ~cross & (np.abs(px * uy - py * ux) <= slack) & (hi >= -slack)
            t = np.where(on & (lo <= length + slack), np.minimum(t, lo), t)
        return np.maximum(t, 0.0)
