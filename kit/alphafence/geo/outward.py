"""Conservative (outward) polygon simplification.

Douglas-Peucker and Visvalingam (``shapely.simplify``) may cut into a polygon; a fence
simplified that way could leave part of a restricted area outside. Shapely/GEOS expose no
outer-hull simplifier, so this module provides one: a greedy sequence of operations each of
which only *adds* area, cheapest first:

* removing a reflex vertex (the triangle it cuts out is filled in), and
* collapsing an edge of two convex vertices onto the point where its neighbouring edges,
  extended, meet (the triangle beyond the edge is added).

An operation is applied only if it keeps the ring simple (no other vertex in the added
triangle, no edge crossing it). Operations of height <= ``tolerance`` metres are always
applied; larger ones only while the ring has more than ``max_vertices`` vertices. Running it
on a clockwise ring instead simplifies *inward* (each operation only removes area), which
keep-in fences use.
"""

from __future__ import annotations

import heapq
import math
from itertools import chain

import numpy as np
import shapely

from alphafence.geo.rings import (
    fill_blocked,
    prereduce,
    ring_coords,
    ring_covers,
    signed_area,
    valid_ring,
)

_EPS = 1e-12
MIN_VERTICES = 4  # any convex polygon of 5+ vertices has an edge whose neighbours meet


def _ops(out, i, st, p, a, b, q, reach, prune, hypot=math.hypot, eps=_EPS):
    """Append vertex ``i``'s operations no higher than ``prune`` to ``out`` as heap entries
    ``(area, height, kind, i, st, X)``; ``a`` is its position, ``p`` the vertex before it,
    ``b`` the one after and ``q`` the one after ``b`` (the ring has 3 vertices or more).

    Kind 0 removes ``a`` if it is reflex. Kind 1 collapses edge ``a`` -> ``b`` onto ``X``,
    where edges ``p`` -> ``a`` and ``q`` -> ``b``, extended, meet outside; ``reach`` bounds
    how far (in multiples of an edge's length) ``X`` may lie from the edge, so nearly
    parallel neighbours never throw a vertex across the map."""
    (px, py), (ix, iy), (jx, jy), (qx, qy) = p, a, b, q
    c = (ix - px) * (jy - py) - (iy - py) * (jx - px)
    if not c > 0:
        area = -0.5 * c
        base = hypot(jx - px, jy - py)
        height = 2.0 * area / base if base > 0 else 0.0
        if not height > prune:
            out.append((area, height, 0, i, st, None))
    d1x, d1y, d2x, d2y = ix - px, iy - py, jx - qx, jy - qy
    den = d1x * d2y - d1y * d2x
    if abs(den) < eps:
        return
    wx, wy = jx - ix, jy - iy
    t = (wx * d2y - wy * d2x) / den
    s = (wx * d1y - wy * d1x) / den
    if t <= 0 or s <= 0 or t * hypot(d1x, d1y) > reach or s * hypot(d2x, d2y) > reach:
        return
    x0, x1 = ix + t * d1x, iy + t * d1y
    # nudge X a hair further out, so rounding never leaves a or b outside the new edges
    mx, my = 0.5 * (ix + jx), 0.5 * (iy + jy)
    x0, x1 = x0 + (x0 - mx) * 1e-9, x1 + (x1 - my) * 1e-9
    c = (jx - ix) * (x1 - iy) - (jy - iy) * (x0 - ix)
    if c >= 0:
        return
    area = -0.5 * c
    base = hypot(wx, wy)
    height = 2.0 * area / base if base > 0 else 0.0
    if not height > prune:
        out.append((area, height, 1, i, st, (x0, x1)))


def _greedy(pts, max_vertices, tolerance, check, first=None, reach=None):
    """Greedy outward simplification of a CCW ring; ``check`` verifies simplicity per step;
    ``first``, the ring's first operations if
    :func:`~alphafence.geo.outward_many._first_heaps` found them (and
    ``reach``, the bound on how far an operation may move a vertex, if it measured it).

    Returns the ring, or None when no operation applies (the ring stays as it is)."""
    if first is not None and not first:
        return None  # no operation to start from: the loop below would not run
    n = len(pts)
    P = pts.tolist()
    prev = [n - 1, *range(n - 1)]
    nxt = [*range(1, n), 0]
    alive = [True] * n
    stamp = [0] * n
    if reach is None:
        reach = 2.0 * float((pts.max(axis=0) - pts.min(axis=0)).max()) + 1.0
    # once the ring is within max_vertices (it only shrinks), operations higher than the
    # tolerance never run: they are not even queued
    heap = [] if first is None else list(first)
    prune = tolerance if n <= max_vertices else math.inf
    if first is None:
        for i, p, a, b, q in zip(range(n), P[-1:] + P[:-1], P, P[1:] + P[:1], P[2:] + P[:2]):
            _ops(heap, i, 0, p, a, b, q, reach, prune)
    heapq.heapify(heap)
    pop, push, ops = heapq.heappop, heapq.heappush, _ops
    count = n
    while heap and count > 3:
        area, height, kind, i, st, X = pop(heap)
        if not alive[i] or stamp[i] != st:
            continue
        if count <= max_vertices and height > tolerance:
            continue
        if kind == 0:
            p, q = prev[i], nxt[i]
            if check and fill_blocked(P, alive, nxt, (P[p], P[i], P[q]), (p, i, q), None):
                continue
            alive[i] = False
            nxt[p], prev[q] = q, p
            touched = (prev[p], p, q)
        else:
            p, j = prev[i], nxt[i]
            q = nxt[j]
            if check and fill_blocked(
                P, alive, nxt, (P[i], X, P[j]), (i, j), ((P[i], X), (X, P[j]), (p, i, j))
            ):
                continue
            P[i] = X
            alive[j] = False
            nxt[i], prev[q] = q, i
            touched = (prev[p], p, i, q)
        count -= 1
        prune = tolerance if count <= max_vertices else math.inf
        new = []
        for v in touched:
            stamp[v] = st = stamp[v] + 1
            j = nxt[v]
            ops(new, v, st, P[prev[v]], P[v], P[j], P[nxt[j]], reach, prune)
        for op in new:
            push(heap, op)
    if count == n:
        return None
    start = alive.index(True)
    out = [P[start]]
    v = nxt[start]
    while v != start:
        out.append(P[v])
        v = nxt[v]
    return np.fromiter(chain.from_iterable(out), float, 2 * count).reshape(count, 2)


def simplify_ring(pts, max_vertices: int, tolerance: float, outward: bool = True) -> np.ndarray:
    """Simplify a simple ring, only ever adding area (``outward``) or only removing it.

    A fast pass without per-step simplicity checks is tried first and kept when the result
    is a valid ring containing (outward) or contained in (inward) the input; otherwise the
    checked pass runs.

    Parameters
    ----------
    pts : array_like or shapely.LinearRing
        The ring's vertices, (n, 2), either orientation.
    max_vertices : int
        Operations higher than ``tolerance`` run while the ring has more vertices than this
        (at least 4).
    tolerance : float
        Operations at most this high (metres) always run.
    outward : bool
        Only add area (else only remove it).

    Returns
    -------
    ndarray, shape (m, 2)
        The vertices, in the input's orientation, not closed.

    Examples
    --------
    >>> import shapely
    >>> disc = shapely.Point(0, 0).buffer(100, quad_segs=16)
    >>> octagon = shapely.Polygon(simplify_ring(disc.exterior, 8, 0.0))
    >>> len(octagon.exterior.coords) - 1, octagon.covers(disc)
    (8, True)
    """
    return _simplify(ring_coords(pts), max_vertices, tolerance, outward)[0]


def _orient(pts, outward):
    """``pts`` (clean, 4 vertices or more) in the orientation simplified, and whether that
    flipped them."""
    area = signed_area(pts)
    flip = (area < 0) if outward else (area > 0)
    return (pts[::-1] if flip else pts), flip


def _simplify(pts, max_vertices, tolerance, outward, given=None, same=False, first=None):
    """:func:`simplify_ring` of clean vertices ``pts``: the vertices, and their polygon when
    one was built (else None). ``given``, a polygon of ``pts``' vertices (any orientation),
    spares building one for the check; if ``same``, its exterior holds ``pts`` as they are
    and it is the polygon of a ring left as it is. ``first``: ``(oriented pts, flipped,
    first operations, :func:`_fast_pass`)`` when
    :func:`~alphafence.geo.outward_many.simplify_polygons` found them."""
    kept = given if same else None
    if len(pts) <= 3:
        return pts, kept
    max_vertices = max(MIN_VERTICES, int(max_vertices))
    if first is None:
        pts, flip = _orient(pts, outward)
        heap, fast = None, _fast_pass(pts, flip, max_vertices, tolerance, outward, given)
    else:
        pts, flip, heap, fast = first

    # the flipped ring is simplified "outward" in its own orientation: for inward
    # simplification that means the result must lie inside the input
    def ok(out):
        return ring_covers(out, pts) if outward else (valid_ring(out) and ring_covers(pts, out))

    out, poly, covers = fast
    if out is None:  # no operation applies (nor would one checked): the ring as it is
        return (pts[::-1] if flip else pts), kept
    final = out[::-1] if flip else out
    if covers or ok(out):
        return final, poly
    out = _greedy(pts, max_vertices, tolerance, True, heap)
    if out is None or not ok(out):  # numerically degenerate input: leave it as it is
        return (pts[::-1] if flip else pts), kept
    return (out[::-1] if flip else out), None


def _fast_pass(pts, flip, max_vertices, tolerance, outward, given):
    """The unchecked pass over oriented ``pts``: its ring (None when no operation applies),
    that ring's polygon, and whether both polygons are valid and the result covers the input
    (outward) or lies in it. When that holds the check of :func:`_simplify` holds: validity
    and covers do not depend on orientation; when it fails, the check decides."""
    out = _greedy(pts, max_vertices, tolerance, False)
    if out is None:
        return None, None, False
    poly = shapely.Polygon(out[::-1] if flip else out)
    if poly.is_valid:
        inner = given if given is not None else shapely.Polygon(pts)
        if inner.is_valid and (poly.covers(inner) if outward else inner.covers(poly)):
            return out, poly, True
    return out, poly, False


def simplify_polygon(poly, max_vertices: int, tolerance: float, outward: bool = True):
    """A polygon's exterior simplified outward (containing it) or inward (inside it).

    Rings of more than twice ``max_vertices`` are first brought near that by
    :func:`prereduce` (outward only); an outward ring that cannot be brought within
    ``max_vertices`` is replaced by its convex hull, simplified.

    Parameters
    ----------
    poly : shapely.Polygon
        Holes are ignored.
    max_vertices : int
        The most vertices wanted (at least 4 are kept).
    tolerance : float
        Operations at most this high (metres) always run.
    outward : bool
        Contain ``poly`` (keep-out fences) rather than lie inside it (keep-in fences).

    Returns
    -------
    shapely.Polygon

    Examples
    --------
    >>> import shapely
    >>> disc = shapely.Point(0, 0).buffer(100, quad_segs=16)
    >>> outer = simplify_polygon(disc, 8, 0.0)
    >>> len(outer.exterior.coords) - 1, outer.covers(disc), round(outer.area)
    (8, True, 33137)
    >>> inner = simplify_polygon(disc, 8, 0.0, outward=False)
    >>> disc.covers(inner), round(inner.area)
    (True, 27810)
    """
    ring = poly.exterior
    pts, given, same = _prepare(
        poly, ring_coords(ring), shapely.get_num_coordinates(ring),
        shapely.get_num_interior_rings(poly), shapely.has_z(poly), max_vertices, outward,
    )  # fmt: skip
    pts, result = _simplify(pts, max_vertices, tolerance, outward, given, same)
    if result is None:
        result = shapely.Polygon(pts)
    return _within_budget(pts, result, max_vertices, tolerance, outward)


def _within_budget(pts, result, max_vertices, tolerance, outward):
    """``result`` (the polygon of ``pts``), or, if outward and longer than ``max_vertices``,
    its convex hull simplified."""
    if outward and len(pts) > max_vertices:
        hull = ring_coords(shapely.convex_hull(result).exterior)
        pts = simplify_ring(hull, max_vertices, tolerance, True)
        result = shapely.Polygon(pts)
    return result


def _prepare(poly, pts, count, holes, has_z, max_vertices, outward):
    """``poly``'s clean exterior vertices (given as ``pts``, from ``count`` coordinates;
    brought near ``2 * max_vertices`` if outward and longer), the polygon standing for them
    if it has no holes, and whether its exterior holds them as they are."""
    given = poly if holes == 0 else None
    if outward and len(pts) > 2 * max_vertices:
        if signed_area(pts) < 0:
            pts = pts[::-1]
        pts = ring_coords(prereduce(pts, 2 * max_vertices))
        given = None
    elif len(pts) > 1 and pts[0].tolist() == pts[-1].tolist():
        pts = ring_coords(pts)  # what simplify_ring's own ring_coords would do
    same = given is not None and len(pts) + 1 == count
    return pts, given, same and not has_z
