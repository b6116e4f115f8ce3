"""Rings as (n, 2) arrays of vertices (not closed): their vertices without repeats, signed
area, validity and containment, as the simplifiers check them; long rings brought near a
target size outward (shifted Douglas-Peucker) before the greedy simplification; whether a
boundary keeps clear of what it holds."""

from __future__ import annotations

import numpy as np
import shapely
import shapely.errors


def ring_coords(ring) -> np.ndarray:
    """Vertices of a ring or (n, 2) array without the closing duplicate or repeats.

    Examples
    --------
    >>> import shapely
    >>> ring_coords(shapely.box(0, 0, 1, 1).exterior).tolist()
    [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]]
    """
    given = isinstance(ring, np.ndarray)
    pts = np.asarray(ring if given else shapely.get_coordinates(ring), float)[:, :2]
    if len(pts) > 1 and pts[0].tolist() == pts[-1].tolist():
        pts = pts[:-1]
    if len(pts) > 1:
        repeat = (pts[1:] == pts[:-1]).all(axis=1)  # a vertex equal to the one before
        if repeat.any():
            keep = np.ones(len(pts), bool)
            keep[1:] = ~repeat
            return pts[keep]
    return pts.copy() if given else pts


def signed_area(pts) -> float:
    """Area of the ring through ``pts`` ((n, 2), not closed): positive counter-clockwise.

    Examples
    --------
    >>> import numpy as np
    >>> signed_area(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))
    1.0
    """
    x, y = pts[:, 0], pts[:, 1]
    # np.roll(a, -1) without its overhead: the same arrays, so the same sums
    y1 = np.concatenate((y[1:], y[:1]))
    x1 = np.concatenate((x[1:], x[:1]))
    return 0.5 * float(np.dot(x, y1) - np.dot(x1, y))


def valid_ring(pts) -> bool:
    """Whether ``pts`` ((n, 2), not closed) make a valid polygon ring of at least 3 vertices."""
    return len(pts) >= 3 and shapely.Polygon(pts).is_valid


def ring_covers(outer_pts, inner_pts) -> bool:
    """Is ``outer`` a valid ring covering ``inner`` (up to rounding in the last digits)?

    Examples
    --------
    >>> import numpy as np
    >>> big = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    >>> ring_covers(big, big / 2), ring_covers(big / 2, big)
    (True, False)
    """
    outer = shapely.Polygon(outer_pts)
    if not outer.is_valid:
        return False
    inner = shapely.Polygon(inner_pts)
    try:
        if outer.covers(inner):
            return True
        return shapely.difference(inner, outer).area <= 1e-9 * max(inner.area, 1.0)
    except shapely.errors.GEOSException:
        return False


def fill_blocked(P, alive, nxt, tri, corners, segments) -> bool:
    """Would filling triangle ``tri`` break the simplicity of a ring being simplified?

    ``P`` holds the vertices, ``alive`` which of them are left and ``nxt`` each one's next;
    a live vertex other than ``corners`` inside or on ``tri`` blocks it, and so does an edge
    (not starting at a vertex in the last item of ``segments``) crossing one of the other
    items of ``segments`` (the new edges).
    """
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
            if segments_cross(A, B, C, D):
                return True
    return False


def segments_cross(A, B, C, D) -> bool:
    """Do segments A-B and C-D meet (touching counts)?"""
    if max(C[0], D[0]) < min(A[0], B[0]) or min(C[0], D[0]) > max(A[0], B[0]):
        return False
    if max(C[1], D[1]) < min(A[1], B[1]) or min(C[1], D[1]) > max(A[1], B[1]):
        return False
    o1 = (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0])
    o2 = (B[0] - A[0]) * (D[1] - A[1]) - (B[1] - A[1]) * (D[0] - A[0])
    o3 = (D[0] - C[0]) * (A[1] - C[1]) - (D[1] - C[1]) * (A[0] - C[0])
    o4 = (D[0] - C[0]) * (B[1] - C[1]) - (D[1] - C[1]) * (B[0] - C[0])
    return o1 * o2 <= 0 and o3 * o4 <= 0


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
    nxt, prv = np.arange(1, m + 1), np.arange(-1, m - 1)  # the next and previous kept one
    nxt[-1] = 0
    a = pts[keep]
    b = pts[keep[nxt]]
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    if np.any(length == 0):
        return None
    normal = np.column_stack([d[:, 1], -d[:, 0]]) / length[:, None]  # right = outside (CCW)
    # every vertex belongs to the kept edge that starts at or before it (vertices before the
    # first kept one wrap to the last edge): from the first kept vertex on, edge by edge
    order = np.r_[keep[0] : n, 0 : keep[0]]
    seg = np.repeat(np.arange(m), np.diff(np.r_[keep, n + keep[0]]))
    rel = pts[order] - a[seg]
    dev = rel[:, 0] * normal[seg, 0] + rel[:, 1] * normal[seg, 1]
    push = np.maximum(np.maximum.reduceat(dev, keep - keep[0]), 0.0)
    # the vertex where an edge ends also belongs to it
    end = b - a
    push = np.maximum(push, end[:, 0] * normal[:, 0] + end[:, 1] * normal[:, 1])
    push = np.maximum(push, 0.0) * (1 + 1e-9) + 1e-9
    a2 = a + normal * push[:, None]
    # intersect edge k-1 with edge k
    d1, d2 = d[prv], d
    den = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    w = a2 - a2[prv]
    with np.errstate(divide="ignore", invalid="ignore"):  # parallel edges: t is not finite
        t = (w[:, 0] * d2[:, 1] - w[:, 1] * d2[:, 0]) / den
        x = a2[prv] + t[:, None] * d1
        far = ~np.isfinite(t) | (np.hypot(*(x - a).T) > 4.0 * (push + push[prv]) + 1e-6)
    # a vertex per kept one: the meeting point, or where they are far apart, a bevel from
    # the end of pushed edge k-1 to the start of pushed edge k
    room = 1 + far
    at = np.cumsum(room) - room
    out = np.empty((int(room.sum()), 2))
    out[at] = np.where(far[:, None], a2[prv] + d1, x)
    out[at[far] + 1] = a2[far]
    return out


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


def rings_coords(rings):
    """:func:`ring_coords` of each ring of an array of rings (or of polygons without holes,
    whose coordinates are their exterior's), from one coordinate fetch.

    Returns
    -------
    pts : list of ndarray
        Each ring's vertices, as :func:`ring_coords` gives them.
    counts : ndarray of int
        Each ring's number of coordinates (closing one included).
    closed : ndarray of bool
        Whether a ring's vertices still end where they start (two or more of them).

    Examples
    --------
    >>> import shapely
    >>> rings = shapely.get_exterior_ring([shapely.box(0, 0, 1, 1), shapely.box(0, 0, 2, 2)])
    >>> pts, counts, closed = rings_coords(rings)
    >>> [p.tolist() == ring_coords(r).tolist() for p, r in zip(pts, rings)], counts.tolist()
    ([True, True], [5, 5])
    """
    xy, at = shapely.get_coordinates(rings, return_index=True)
    counts = np.bincount(at, minlength=len(rings))
    end = np.cumsum(counts)
    start = end - counts
    drop = np.zeros(len(xy), bool)
    drop[1:] = (xy[1:] == xy[:-1]).all(axis=1)  # a vertex equal to the one before
    drop[start[counts > 0]] = False
    two = np.flatnonzero(counts > 1)
    closed = (xy[start[two]] == xy[end[two] - 1]).all(axis=1)
    drop[end[two] - 1] = closed | drop[end[two] - 1]  # the closing duplicate, or a repeat
    kept = np.cumsum(counts) - np.cumsum(np.bincount(at[drop], minlength=len(rings)))
    xy = xy[~drop]
    sizes = np.diff(kept, prepend=0)
    closed = sizes > 1
    closed[closed] = (xy[(kept - sizes)[closed]] == xy[kept[closed] - 1]).all(axis=1)
    return np.split(xy, kept[:-1]), counts, closed


def ring_signs(rings) -> np.ndarray:
    """The sign (1, -1 or 0) of :func:`signed_area` of each ring ((n, 2) arrays, n >= 1),
    summed for all rings at once and, where rounding could tell another sign, by
    :func:`signed_area` itself (so always the sign it gives).

    Examples
    --------
    >>> import numpy as np
    >>> square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> ring_signs([square, square[::-1], square[:2]]).tolist()
    [1, -1, 0]
    """
    sizes = np.fromiter(map(len, rings), int, len(rings))
    xy = np.concatenate(rings)
    start = np.cumsum(sizes) - sizes
    nxt = np.arange(1, len(xy) + 1)
    nxt[start + sizes - 1] = start
    x, y = xy[:, 0], xy[:, 1]
    with np.errstate(over="ignore", invalid="ignore"):
        a, b = x * y[nxt], x[nxt] * y
        twice = np.add.reduceat(a - b, start)
        # both sums err by at most (n + 2) units of the last place of the terms' magnitude;
        # eight times that (plus what underflow may lose) and the sign cannot be another
        bound = np.add.reduceat(np.abs(a) + np.abs(b), start) * (sizes + 2) * 2.0**-50 + 1e-300
        sure = np.abs(twice) > bound
    signs = np.where(sure, np.sign(twice), 0).astype(int)
    for k in np.flatnonzero(~sure).tolist():
        area = signed_area(rings[k])
        signs[k] = 1 if area > 0 else -1 if area < 0 else 0
    return signs


def ring_polygons(rings) -> np.ndarray:
    """The polygon of each ring ((n, 2) arrays, 3 vertices or more each), closed as
    ``shapely.Polygon`` closes them, built in one call.

    Examples
    --------
    >>> import numpy as np
    >>> ring_polygons([np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])])[0].wkt
    'POLYGON ((0 0, 1 0, 0 1, 0 0))'
    """
    if not len(rings):
        return np.empty(0, dtype=object)
    sizes = np.fromiter(map(len, rings), int, len(rings))
    at = np.repeat(np.arange(len(rings)), sizes)
    return shapely.polygons(shapely.linearrings(np.concatenate(rings), indices=at))


PREPARED_FROM = 1_000  # boundary vertices from which clear_of indexes a boundary first


def clear_of(boundaries, geoms, distance_m):
    """Whether each boundary keeps at least ``distance_m`` from its geometry (vectorised):
    ``shapely.distance(boundary, geom) >= distance_m``.

    Boundaries of :data:`PREPARED_FROM` vertices or more are prepared (indexed), and the
    distance is measured only where one comes within reach: near a pole a fence's lon/lat
    reading has some 1e5 vertices, where a plain distance takes seconds and this milliseconds.
    The others, most fences, are measured plainly (indexing each would cost more).

    Examples
    --------
    >>> fence, house = shapely.box(-50, -50, 50, 50), shapely.box(-10, -10, 10, 10)
    >>> bool(clear_of(fence.boundary, house, 40.0)), bool(clear_of(fence.boundary, house, 40.1))
    (True, False)
    """
    one = isinstance(boundaries, shapely.Geometry)
    boundaries = np.atleast_1d(np.asarray(boundaries, dtype=object))
    geoms = np.broadcast_to(np.asarray(geoms, dtype=object), boundaries.shape)
    distance_m = np.broadcast_to(np.asarray(distance_m, dtype=float), boundaries.shape)
    clear = np.ones(boundaries.shape, dtype=bool)
    large = shapely.get_num_coordinates(boundaries) >= PREPARED_FROM
    small = np.flatnonzero(~large)
    if small.size:  # (an empty boundary keeps clear of anything, as it does below)
        clear[small] = ~(shapely.distance(boundaries[small], geoms[small]) < distance_m[small])
    large = np.flatnonzero(large)
    if large.size:
        shapely.prepare(boundaries[large])
        near = large[shapely.dwithin(boundaries[large], geoms[large], distance_m[large])]
        if near.size:  # within reach, or exactly at it: measured
            clear[near] = shapely.distance(boundaries[near], geoms[near]) >= distance_m[near]
    return bool(clear[0]) if one else clear
