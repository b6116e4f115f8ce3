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

from alphafence.geo.rings import ring_coords, ring_covers, signed_area, valid_ring

_EPS = 1e-12
MIN_VERTICES = 4  # any convex polygon of 5+ vertices has an edge whose neighbours meet


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


def _greedy(pts, max_vertices, tolerance, check):
    """Greedy outward simplification of a CCW ring; ``check`` verifies simplicity per step.

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
    heap = []
    prune = tolerance if n <= max_vertices else math.inf
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
            if check and _blocked(P, alive, nxt, (P[p], P[i], P[q]), (p, i, q), None):
                continue
            alive[i] = False
            nxt[p], prev[q] = q, p
            touched = (prev[p], p, q)
        else:
            p, j = prev[i], nxt[i]
            q = nxt[j]
            if check and _blocked(
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


def _blocked(P, alive, nxt, tri, corners, segments):
    """Would filling triangle ``tri`` break the ring's simplicity?"""
    (ax, ay), (bx, by), (cx, cy) = tri
    lox, hix = min(ax, bx, cx), max(ax, bx, cx)
    loy, hiy = min(ay, by, cy), max(ay, by, cy)
    for v, ok in enumerate(alive):
        if not ok or v in corners:
            continue
        x, y = P[v]
        if x < lox or x > hix or y < loy or y > hiy:
            continue
        d1 = (bx - ax) * (y - ay) - (by - ay) * (x - ax)
        d2 = (cx - bx) * (y - by) - (cy - by) * (x - bx)
        d3 = (ax - cx) * (y - cy) - (ay - cy) * (x - cx)
        if not ((d1 < 0 or d2 < 0 or d3 < 0) and (d1 > 0 or d2 > 0 or d3 > 0)):
            return True
    if segments is None:
        return False
    *segs, skip = segments
    for u, ok in enumerate(alive):
        if not ok or u in skip:
            continue
        C, D = P[u], P[nxt[u]]
        for A, B in segs:
            if _crosses(A, B, C, D):
                return True
    return False


def _crosses(A, B, C, D):
    if max(C[0], D[0]) < min(A[0], B[0]) or min(C[0], D[0]) > max(A[0], B[0]):
        return False
    if max(C[1], D[1]) < min(A[1], B[1]) or min(C[1], D[1]) > max(A[1], B[1]):
        return False
    o1 = (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0])
    o2 = (B[0] - A[0]) * (D[1] - A[1]) - (B[1] - A[1]) * (D[0] - A[0])
    o3 = (D[0] - C[0]) * (A[1] - C[1]) - (D[1] - C[1]) * (A[0] - C[0])
    o4 = (D[0] - C[0]) * (B[1] - C[1]) - (D[1] - C[1]) * (B[0] - C[0])
    return o1 * o2 <= 0 and o3 * o4 <= 0


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


def _simplify(pts, max_vertices, tolerance, outward, given=None, same=False):
    """:func:`simplify_ring` of clean vertices ``pts``: the vertices, and their polygon when
    one was built (else None). ``given``, a polygon of ``pts``' vertices (any orientation),
    spares building one for the check; if ``same``, its exterior holds ``pts`` as they are
    and it is the polygon of a ring left as it is."""
    kept = given if same else None
    if len(pts) <= 3:
        return pts, kept
    area = signed_area(pts)
    flip = (area < 0) if outward else (area > 0)
    if flip:
        pts = pts[::-1]
    max_vertices = max(MIN_VERTICES, int(max_vertices))

    # the flipped ring is simplified "outward" in its own orientation: for inward
    # simplification that means the result must lie inside the input
    def ok(out):
        return ring_covers(out, pts) if outward else (valid_ring(out) and ring_covers(pts, out))

    out = _greedy(pts, max_vertices, tolerance, check=False)
    if out is None:  # no operation applies (nor would one checked): the ring as it is
        return (pts[::-1] if flip else pts), kept
    final = out[::-1] if flip else out
    # ok(out) first on the result's own polygon: validity and covers do not depend on
    # orientation, so when they hold ok(out) holds; when they fail, ok(out) decides
    poly = shapely.Polygon(final)
    if poly.is_valid:
        inner = given if given is not None else shapely.Polygon(pts)
        if poly.covers(inner) if outward else inner.is_valid and inner.covers(poly):
            return final, poly
    if ok(out):
        return final, poly
    out = _greedy(pts, max_vertices, tolerance, check=True)
    if out is None or not ok(out):  # numerically degenerate input: leave it as it is
        return (pts[::-1] if flip else pts), kept
    return (out[::-1] if flip else out), None


def shifted_dp(pts, tol):
    """Fast outward pre-reduction of a CCW ring (vectorised).

    Douglas-Peucker (GEOS) picks a subset of the vertices; each kept edge is then pushed
    outward, parallel to itself, just far enough that the chain of vertices it replaced lies
    on its inner side, and consecutive pushed edges are joined at their intersection (or,
    where they are nearly parallel, by a short bevel). Returns the new ring, or None when the
    subset is degenerate; callers verify containment.
    """
    return _shifted(pts, _dp(shapely.Polygon(pts), tol))


def _dp(ring, tol):
    """The vertices Douglas-Peucker (GEOS, topology preserving) keeps of polygon ``ring``."""
    return ring_coords(shapely.simplify(ring, tol, preserve_topology=True).exterior)


def _shifted(pts, spts, index=None):
    """:func:`shifted_dp` given the kept vertices ``spts`` (and ``pts``' vertex -> index)."""
    n = len(pts)
    if len(spts) < 3 or len(spts) >= n:
        return None
    if index is None:
        index = {tuple(p): k for k, p in enumerate(pts.tolist())}
    try:
        keep = np.array(sorted(index[tuple(p)] for p in spts.tolist()))
    except KeyError:
        return None
    m = len(keep)
    a = pts[keep]
    b = pts[np.roll(keep, -1)]
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    if np.any(length == 0):
        return None
    normal = np.column_stack([d[:, 1], -d[:, 0]]) / length[:, None]  # right = outside (CCW)
    # every vertex belongs to the kept edge that starts at or before it
    seg = np.searchsorted(keep, np.arange(n), side="right") - 1
    seg[seg < 0] = m - 1  # vertices before the first kept one wrap to the last edge
    rel = pts - a[seg]
    dev = rel[:, 0] * normal[seg, 0] + rel[:, 1] * normal[seg, 1]
    push = np.zeros(m)
    np.maximum.at(push, seg, dev)
    # the vertex where an edge ends also belongs to it
    nxt = np.roll(np.arange(m), -1)
    end = pts[keep[nxt]] - a
    push = np.maximum(push, end[:, 0] * normal[:, 0] + end[:, 1] * normal[:, 1])
    push = np.maximum(push, 0.0) * (1 + 1e-9) + 1e-9
    a2 = a + normal * push[:, None]
    # intersect edge k-1 with edge k
    prv = np.roll(np.arange(m), 1)
    d1, d2 = d[prv], d
    den = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    w = a2 - a2[prv]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, 0] * d2[:, 1] - w[:, 1] * d2[:, 0]) / den
    x = a2[prv] + t[:, None] * d1
    far = ~np.isfinite(t) | (np.hypot(*(x - a).T) > 4.0 * (push + push[prv]) + 1e-6)
    out = []
    b_prev = a2[prv] + d1  # end of pushed edge k-1
    for k in range(m):
        if far[k]:
            out.append(b_prev[k])
            out.append(a2[k])
        else:
            out.append(x[k])
    return np.array(out)


def prereduce(pts, target):
    """Bring a CCW ring near ``target`` vertices with :func:`shifted_dp`, verified."""
    if len(pts) <= target:
        return pts
    span = float(np.ptp(pts, axis=0).max())
    tol = max(span * 1e-4, 1e-3)
    ring = shapely.Polygon(pts)
    index = {tuple(p): k for k, p in enumerate(pts.tolist())}
    while tol < span:
        spts = _dp(ring, tol)
        # the shifted ring has a vertex or two per kept one: too many kept, too long
        if len(spts) <= target:
            cand = _shifted(pts, spts, index)
            if cand is not None and len(cand) <= target and ring_covers(cand, pts):
                return cand
        tol *= 2.0
    return pts


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
    same = same and not shapely.has_z(poly)
    pts, result = _simplify(pts, max_vertices, tolerance, outward, given, same)
    if result is None:
        result = shapely.Polygon(pts)
    if outward and len(pts) > max_vertices:
        hull = ring_coords(shapely.convex_hull(result).exterior)
        pts = simplify_ring(hull, max_vertices, tolerance, True)
        result = shapely.Polygon(pts)
    return result
