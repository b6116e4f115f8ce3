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
BATCH_MIN_VERTICES = 160  # fewer vertices in all: each ring's own pass is cheaper


def _ops(out, i, st, p, a, b, q, reach, prune):
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
        base = math.hypot(jx - px, jy - py)
        height = 2.0 * area / base if base > 0 else 0.0
        if not height > prune:
            out.append((area, height, 0, i, st, None))
    d1x, d1y, d2x, d2y = ix - px, iy - py, jx - qx, jy - qy
    den = d1x * d2y - d1y * d2x
    if abs(den) < _EPS:
        return
    wx, wy = jx - ix, jy - iy
    t = (wx * d2y - wy * d2x) / den
    s = (wx * d1y - wy * d1x) / den
    if t <= 0 or s <= 0 or t * math.hypot(d1x, d1y) > reach or s * math.hypot(d2x, d2y) > reach:
        return
    x0, x1 = ix + t * d1x, iy + t * d1y
    # nudge X a hair further out, so rounding never leaves a or b outside the new edges
    mx, my = 0.5 * (ix + jx), 0.5 * (iy + jy)
    x0, x1 = x0 + (x0 - mx) * 1e-9, x1 + (x1 - my) * 1e-9
    c = (jx - ix) * (x1 - iy) - (jy - iy) * (x0 - ix)
    if c >= 0:
        return
    area = -0.5 * c
    base = math.hypot(wx, wy)
    height = 2.0 * area / base if base > 0 else 0.0
    if not height > prune:
        out.append((area, height, 1, i, st, (x0, x1)))


def _greedy(pts, max_vertices, tolerance, check, first=None):
    """Greedy outward simplification of a CCW ring; ``check`` verifies simplicity per step;
    ``first``, the ring's first operations if :func:`_first_heaps` found them.

    Returns the ring, or None when no operation applies (the ring stays as it is)."""
    n = len(pts)
    P = [tuple(p) for p in pts.tolist()]
    prev = [(k - 1) % n for k in range(n)]
    nxt = [(k + 1) % n for k in range(n)]
    alive = [True] * n
    stamp = [0] * n
    span = float((pts.max(axis=0) - pts.min(axis=0)).max())
    reach = 2.0 * span + 1.0
    # once the ring is within max_vertices (it only shrinks), operations higher than the
    # tolerance never run: they are not even queued
    heap = [] if first is None else list(first)
    prune = tolerance if n <= max_vertices else math.inf
    if first is None:
        for i, p, a, b, q in zip(range(n), P[-1:] + P[:-1], P, P[1:] + P[:1], P[2:] + P[:2]):
            _ops(heap, i, 0, p, a, b, q, reach, prune)
    heapq.heapify(heap)
    count = n
    changed = False
    while heap and count > 3:
        area, height, kind, i, st, X = heapq.heappop(heap)
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
        changed = True
        prune = tolerance if count <= max_vertices else math.inf
        new = []
        for v in touched:
            stamp[v] += 1
            j = nxt[v]
            _ops(new, v, stamp[v], P[prev[v]], P[v], P[j], P[nxt[j]], reach, prune)
        for op in new:
            heapq.heappush(heap, op)
    if not changed:
        return None
    start = alive.index(True)
    out = [P[start]]
    v = nxt[start]
    while v != start:
        out.append(P[v])
        v = nxt[v]
    return np.array(out)


def _first_heaps(rings, max_vertices, tolerance):
    """The first operations of many oriented rings (4 vertices or more each) at once: for
    each ring the heap entries :func:`_greedy`'s pass of :func:`_ops` finds (None where a
    few rings make the pass itself cheaper). The arithmetic is ``_ops``', elementwise, so
    every value is the same float; ``_ops`` measures lengths with ``math.hypot``, which may
    differ from ``np.hypot`` in the last bit, so ``np.hypot`` only drops operations that are
    clearly too high or too far, and the others are measured again as ``_ops`` does."""
    if not rings or sum(map(len, rings)) < BATCH_MIN_VERTICES:
        return [None] * len(rings)
    sizes = np.array([len(r) for r in rings], int)
    xy = np.concatenate(rings)
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    n = np.repeat(sizes, sizes)
    i = np.arange(len(xy)) - start
    x, y = xy[:, 0], xy[:, 1]
    (px, py), (jx, jy), (qx, qy) = (xy[start + (i + k) % n].T for k in (-1, 1, 2))
    offsets = np.cumsum(sizes) - sizes
    span = (np.maximum.reduceat(xy, offsets) - np.minimum.reduceat(xy, offsets)).max(axis=1)
    reach = np.repeat(2.0 * span + 1.0, sizes)
    prune = np.repeat(np.where(sizes <= max_vertices, tolerance, math.inf), sizes)
    loose = 1.0 + 1e-9  # far above the last-bit differences of the two hypots
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c = (x - px) * (jy - py) - (y - py) * (jx - px)
        area0, bx, by = -0.5 * c, jx - px, jy - py
        keep0 = ~(c > 0) & ~(2.0 * area0 / np.hypot(bx, by) > prune * loose)
        d1x, d1y, d2x, d2y = x - px, y - py, jx - qx, jy - qy
        den = d1x * d2y - d1y * d2x
        wx, wy = jx - x, jy - y
        t = (wx * d2y - wy * d2x) / den
        s = (wx * d1y - wy * d1x) / den
        x0, x1 = x + t * d1x, y + t * d1y
        x0, x1 = x0 + (x0 - 0.5 * (x + jx)) * 1e-9, x1 + (x1 - 0.5 * (y + jy)) * 1e-9
        c = (jx - x) * (x1 - y) - (jy - y) * (x0 - x)
        area1 = -0.5 * c
        keep1 = ~(np.abs(den) < _EPS) & ~(t <= 0) & ~(s <= 0) & ~(c >= 0)
        keep1 &= ~(2.0 * area1 / np.hypot(wx, wy) > prune * loose)
        far = np.maximum(t * np.hypot(d1x, d1y), s * np.hypot(d2x, d2y))
        keep1 &= ~(far > reach * loose)
        near = ~(far > reach / loose)  # within reach whichever hypot measures it
    ring = np.repeat(np.arange(len(rings)), sizes)
    heaps = [[] for _ in rings]
    hypot = math.hypot
    v = np.flatnonzero(keep0)
    for r, k, a, ux, uy, cut in zip(*(col[v].tolist() for col in (ring, i, area0, bx, by, prune))):
        base = hypot(ux, uy)
        height = 2.0 * a / base if base > 0 else 0.0
        if not height > cut:
            heaps[r].append((a, height, 0, k, 0, None))
    for v in np.flatnonzero(keep1 & ~near).tolist():  # rare: the reach as _ops measures it
        far = float(reach[v])
        if t[v] * hypot(d1x[v], d1y[v]) > far or s[v] * hypot(d2x[v], d2y[v]) > far:
            keep1[v] = False
    v = np.flatnonzero(keep1)
    cols = (ring, i, area1, wx, wy, x0, x1, prune)
    for r, k, a, ux, uy, X0, X1, cut in zip(*(col[v].tolist() for col in cols)):
        base = hypot(ux, uy)
        height = 2.0 * a / base if base > 0 else 0.0
        if not height > cut:
            heaps[r].append((a, height, 1, k, 0, (X0, X1)))
    return heaps


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
    first operations)`` when :func:`simplify_polygons` found them."""
    kept = given if same else None
    if len(pts) <= 3:
        return pts, kept
    pts, flip, heap = (*_orient(pts, outward), None) if first is None else first
    max_vertices = max(MIN_VERTICES, int(max_vertices))

    # the flipped ring is simplified "outward" in its own orientation: for inward
    # simplification that means the result must lie inside the input
    def ok(out):
        return ring_covers(out, pts) if outward else (valid_ring(out) and ring_covers(pts, out))

    out = _greedy(pts, max_vertices, tolerance, False, heap)
    if out is None:  # no operation applies (nor would one checked): the ring as it is
        return (pts[::-1] if flip else pts), kept
    final = out[::-1] if flip else out
    # ok(out) first on the result's own polygon: validity and covers do not depend on
    # orientation, so when they hold ok(out) holds; when they fail, ok(out) decides
    poly = shapely.Polygon(final)
    if poly.is_valid:
        inner = given if given is not None else shapely.Polygon(pts)
        if inner.is_valid and (poly.covers(inner) if outward else inner.covers(poly)):
            return final, poly
    if ok(out):
        return final, poly
    out = _greedy(pts, max_vertices, tolerance, True, heap)
    if out is None or not ok(out):  # numerically degenerate input: leave it as it is
        return (pts[::-1] if flip else pts), kept
    return (out[::-1] if flip else out), None


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
    return _finish(_prepare(poly, max_vertices, outward), max_vertices, tolerance, outward)


def simplify_polygons(polys, max_vertices: int, tolerance: float, outward: bool = True) -> list:
    """:func:`simplify_polygon` of each polygon, the first operations of all their rings found
    in one vectorised pass (the same polygons as one at a time).

    Parameters
    ----------
    polys : sequence of shapely.Polygon
    max_vertices : int
    tolerance : float
    outward : bool
        As for :func:`simplify_polygon`.

    Returns
    -------
    list of shapely.Polygon
    """
    rings = [_prepare(poly, max_vertices, outward) for poly in polys]
    long = [k for k, (pts, _, _) in enumerate(rings) if len(pts) > 3]
    oriented = [_orient(rings[k][0], outward) for k in long]
    mv = max(MIN_VERTICES, int(max_vertices))
    heaps = _first_heaps([pts for pts, _ in oriented], mv, tolerance)
    first = {k: (pts, flip, heap) for k, (pts, flip), heap in zip(long, oriented, heaps)}
    return [
        _finish(ring, max_vertices, tolerance, outward, first.get(k))
        for k, ring in enumerate(rings)
    ]


def _finish(prepared, max_vertices, tolerance, outward, first=None):
    """The polygon simplified from what :func:`_prepare` made of it."""
    pts, given, same = prepared
    pts, result = _simplify(pts, max_vertices, tolerance, outward, given, same, first)
    if result is None:
        result = shapely.Polygon(pts)
    if outward and len(pts) > max_vertices:
        hull = ring_coords(shapely.convex_hull(result).exterior)
        pts = simplify_ring(hull, max_vertices, tolerance, True)
        result = shapely.Polygon(pts)
    return result


def _prepare(poly, max_vertices, outward):
    """``poly``'s clean exterior vertices (brought near ``2 * max_vertices`` if outward and
    longer), the polygon standing for them if it has no holes, and whether its exterior
    holds them as they are."""
    ring = poly.exterior
    pts = ring_coords(ring)
    given = poly if shapely.get_num_interior_rings(poly) == 0 else None
    if outward and len(pts) > 2 * max_vertices:
        if signed_area(pts) < 0:
            pts = pts[::-1]
        pts = ring_coords(prereduce(pts, 2 * max_vertices))
        given = None
    elif len(pts) > 1 and pts[0].tolist() == pts[-1].tolist():
        pts = ring_coords(pts)  # what simplify_ring's own ring_coords would do
    same = given is not None and len(pts) + 1 == shapely.get_num_coordinates(ring)
    return pts, given, same and not shapely.has_z(poly)
