"""Outward (or inward) simplification of many polygons at once: each polygon is the one
:func:`~alphafence.geo.outward.simplify_polygon` makes of it alone, to the last bit, but the
work around the greedy passes (fetching the rings' vertices, their orientations, their first
operations, building and checking the results) is done for all rings in vectorised passes.
"""

from __future__ import annotations

import math
from itertools import repeat

import numpy as np
import shapely

from alphafence.geo.outward import (
    _EPS,
    MIN_VERTICES,
    _greedy,
    _prepare,
    _simplify,
    _within_budget,
)
from alphafence.geo.rings import ring_polygons, ring_signs, rings_coords

BATCH_MIN_VERTICES = 160  # fewer vertices in all: each ring's own pass is cheaper


def simplify_polygons(polys, max_vertices: int, tolerance: float, outward: bool = True) -> list:
    """:func:`~alphafence.geo.outward.simplify_polygon` of each polygon (the same polygons as
    one at a time), with vectorised passes over all their rings: the vertices fetched, the
    orientations summed, the first operations found, and the unchecked passes' results
    built, validated and checked.

    Parameters
    ----------
    polys : sequence of shapely.Polygon
    max_vertices : int
    tolerance : float
    outward : bool
        As for :func:`~alphafence.geo.outward.simplify_polygon`.

    Returns
    -------
    list of shapely.Polygon
    """
    if not len(polys):
        return []
    polys = _objects(polys)
    holes = shapely.get_num_interior_rings(polys)
    exteriors = polys.copy()  # a polygon without holes has its exterior's coordinates
    exteriors[holes > 0] = shapely.get_exterior_ring(polys[holes > 0])
    coords, counts, closed = rings_coords(exteriors)
    sizes = np.fromiter(map(len, coords), int, len(coords))
    flat, has_z = holes == 0, shapely.has_z(polys)
    # what _prepare makes of a ring neither to bring near 2 * max_vertices nor to clean again
    odd = closed | (sizes > 2 * max_vertices) if outward else closed
    same = flat & (sizes + 1 == counts) & ~has_z
    rings = [
        _prepare(poly, pts, n, h, z, max_vertices, outward) if o else (pts, poly if f else None, s)
        for poly, pts, n, h, z, o, f, s in zip(
            polys.tolist(), coords, counts.tolist(), holes.tolist(), has_z.tolist(),
            odd.tolist(), flat.tolist(), same.tolist(),
        )
    ]  # fmt: skip
    long = [k for k, (pts, _, _) in enumerate(rings) if len(pts) > 3]
    signs = ring_signs([rings[k][0] for k in long]).tolist() if long else []
    oriented = []
    for k, sign in zip(long, signs):
        flip = sign < 0 if outward else sign > 0
        oriented.append((rings[k][0][::-1] if flip else rings[k][0], flip))
    mv = max(MIN_VERTICES, int(max_vertices))
    heaps, reaches = _first_ops([pts for pts, _ in oriented], mv, tolerance)
    givens = [rings[k][1] for k in long]
    fast = _fast_passes(oriented, givens, heaps, reaches, mv, tolerance, outward)
    first = dict(zip(long, ((*o, h, f) for o, h, f in zip(oriented, heaps, fast))))
    done = [
        _simplify(pts, max_vertices, tolerance, outward, given, same, first.get(k))
        for k, (pts, given, same) in enumerate(rings)
    ]
    bare = [k for k, (pts, result) in enumerate(done) if result is None and len(pts) >= 3]
    built = dict(zip(bare, ring_polygons([done[k][0] for k in bare]).tolist()))
    for k, (pts, result) in enumerate(done):
        if result is None:
            result = built[k] if k in built else shapely.Polygon(pts)
        done[k] = _within_budget(pts, result, max_vertices, tolerance, outward)
    return done


def _first_heaps(rings, max_vertices, tolerance):
    """The first operations of many oriented rings (4 vertices or more each) at once: for
    each ring the heap entries :func:`_greedy`'s pass of :func:`_ops` finds (None where a
    few rings make the pass itself cheaper). The arithmetic is ``_ops``', elementwise, so
    every value is the same float; ``_ops`` measures lengths with ``math.hypot``, which may
    differ from ``np.hypot`` in the last bit, so ``np.hypot`` only drops operations that are
    clearly too high or too far, and the others are measured again as ``_ops`` does."""
    return _first_ops(rings, max_vertices, tolerance)[0]


def _first_ops(rings, max_vertices, tolerance):
    """:func:`_first_heaps`, and each ring's reach as :func:`_greedy` measures it (None
    where the heaps are)."""
    if not rings or sum(map(len, rings)) < BATCH_MIN_VERTICES:
        return [None] * len(rings), [None] * len(rings)
    sizes = np.fromiter(map(len, rings), int, len(rings))
    xy = np.concatenate(rings)
    offsets = np.cumsum(sizes) - sizes
    at = np.arange(len(xy))
    i = at - np.repeat(offsets, sizes)  # each vertex's index in its ring
    before, after = at - 1, at + 1
    before[offsets], after[offsets + sizes - 1] = offsets + sizes - 1, offsets
    x, y = xy[:, 0], xy[:, 1]
    (px, py), (jx, jy), (qx, qy) = (xy[k].T for k in (before, after, after[after]))
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
    hypot = math.hypot
    for v in np.flatnonzero(keep1 & ~near).tolist():  # rare: the reach as _ops measures it
        far = float(reach[v])
        if t[v] * hypot(d1x[v], d1y[v]) > far or s[v] * hypot(d2x[v], d2y[v]) > far:
            keep1[v] = False
    ring = np.repeat(np.arange(len(rings)), sizes)
    v0, h0 = _measured(np.flatnonzero(keep0), area0, bx, by, prune)
    v1, h1 = _measured(np.flatnonzero(keep1), area1, wx, wy, prune)
    # each ring's entries in _ops' order: its vertices' removals, then their collapses
    ops0 = list(zip(area0[v0].tolist(), h0, repeat(0), i[v0].tolist(), repeat(0), repeat(None)))
    X = zip(x0[v1].tolist(), x1[v1].tolist())
    ops1 = list(zip(area1[v1].tolist(), h1, repeat(1), i[v1].tolist(), repeat(0), X))
    end0 = np.cumsum(np.bincount(ring[v0], minlength=len(rings))).tolist()
    end1 = np.cumsum(np.bincount(ring[v1], minlength=len(rings))).tolist()
    heaps = [
        ops0[a0:b0] + ops1[a1:b1] for a0, b0, a1, b1 in zip([0, *end0], end0, [0, *end1], end1)
    ]
    return heaps, (2.0 * span + 1.0).tolist()


def _measured(v, area, ux, uy, prune):
    """The operations ``v`` (of heights ``2 area / |u|`` as :func:`_ops` measures them, with
    ``math.hypot``) no higher than their ``prune``, and their heights."""
    base = np.fromiter(map(math.hypot, ux[v].tolist(), uy[v].tolist()), float, len(v))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        height = np.where(base > 0, 2.0 * area[v] / base, 0.0)
    low = ~(height > prune[v])
    return v[low], height[low].tolist()


def _fast_passes(oriented, givens, heaps, reaches, max_vertices, tolerance, outward):
    """:func:`~alphafence.geo.outward._fast_pass` of each oriented ring (``(pts, flipped)``,
    its polygon's stand-in in ``givens``), the polygons built, validated and checked in one
    GEOS call each."""
    outs = [
        _greedy(pts, max_vertices, tolerance, False, heap, reach)
        for (pts, _), heap, reach in zip(oriented, heaps, reaches)
    ]
    done = [k for k, out in enumerate(outs) if out is not None]
    polys = ring_polygons([outs[k][::-1] if oriented[k][1] else outs[k] for k in done])
    fast = [(None, None, False)] * len(outs)
    for k, poly in zip(done, polys.tolist()):
        fast[k] = (outs[k], poly, False)
    valid = [(j, k) for (j, k), ok in zip(enumerate(done), shapely.is_valid(polys)) if ok]
    built = iter(ring_polygons([oriented[k][0] for _, k in valid if givens[k] is None]))
    inner = _objects([next(built) if givens[k] is None else givens[k] for _, k in valid])
    sound = np.flatnonzero(shapely.is_valid(inner))
    outer = polys[[valid[i][0] for i in sound.tolist()]]
    inner = inner[sound]
    covers = shapely.covers(outer, inner) if outward else shapely.covers(inner, outer)
    for i in sound[covers].tolist():
        k = valid[i][1]
        fast[k] = (outs[k], fast[k][1], True)
    return fast


def _objects(items):
    """``items`` as a 1-d object array."""
    out = np.empty(len(items), dtype=object)
    out[:] = items
    return out
