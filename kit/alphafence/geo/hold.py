"""Metric polygons held as their lon/lat vertices will be read: each edge moved away from
the area it protects by the bow of its lon/lat reading (:mod:`alphafence.geo.lonlat`), the
moved lines' meeting points the new vertices, so the polygon keeps its vertex count."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from alphafence.geo.lonlat import READ_TOLERANCE_M, left_bows
from alphafence.geo.rings import ring_coords

MAX_PIECES = 256  # an edge is cut in at most this many: what still bows is checked as read


def _meeting_points(pts, n, push):
    """Where each vertex's two neighbouring edge lines meet once moved right by ``push``,
    and which of them lie farther than 200 pushes, a metre and a tenth of the ring's size
    from the vertex (or nowhere)."""
    c = np.einsum("ij,ij->i", n, pts) + push
    n0, c0 = np.roll(n, 1, axis=0), np.roll(c, 1)  # the edge before each vertex
    det = n0[:, 0] * n[:, 1] - n0[:, 1] * n[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (c0 * n[:, 1] - c * n0[:, 1]) / det
        y = (n0[:, 0] * c - n[:, 0] * c0) / det
    meet = np.column_stack([x, y])
    level = np.maximum(push, np.roll(push, 1))
    # collinear neighbours (an edge cut in pieces): their lines are one, moved by the larger
    same = (np.abs(det) < 1e-12) & (np.einsum("ij,ij->i", n0, n) > 0)
    meet[same] = pts[same] + n[same] * level[same, None]
    size = float(np.ptp(pts, axis=0).max()) if len(pts) else 0.0
    reach = 200.0 * level + 1.0 + 0.1 * size
    return meet, ~(np.hypot(*(meet - pts).T) <= reach)


def _shifted_ring(pts, push):
    """The ring whose edge ``i`` lies at least ``push[i]`` metres right of edge ``i`` of
    ``pts``: neighbouring lines meet at the new vertices. Nearly collinear neighbours moved
    by different amounts would meet far away: both move by the larger. Where lines still
    meet far away or not at all (a hairpin), two vertices cut the corner (a bevel).
    Returns the ring, each edge's push, and which edge of ``pts`` each edge of the ring
    lies along (-1 for a bevel's own edge)."""
    d = np.roll(pts, -1, axis=0) - pts
    length = np.hypot(d[:, 0], d[:, 1])
    n = np.column_stack([d[:, 1], -d[:, 0]]) / length[:, None]  # right normals
    push = np.array(push, float)
    for _ in range(len(pts)):
        meet, far = _meeting_points(pts, n, push)
        if not far.any():
            return meet, push, np.arange(len(pts))
        before = np.roll(push, 1)
        level = np.maximum(push, before)
        grow = far & ((push < level) | (before < level))
        if not grow.any():
            break
        push = np.where(grow, level, push)
        before_idx = (np.flatnonzero(grow) - 1) % len(pts)
        push[before_idx] = np.maximum(push[before_idx], level[grow])
    n0 = np.roll(n, 1, axis=0)
    out, edge_of = [], []
    for i in range(len(pts)):
        if far[i]:
            out.append(pts[i] + n0[i] * (push[i - 1] + 1e-6))
            out.append(pts[i] + n[i] * (push[i] + 1e-6))
            edge_of += [-1, i]  # the bevel's own short edge, then edge i
        else:
            out.append(meet[i])
            edge_of.append(i)
    return np.asarray(out), push, np.asarray(edge_of)


def _densified_on_chords(frame, pts, bows, tolerance_m):
    """``pts`` with vertices added along the metric edges whose lon/lat reading bows more
    than ``tolerance_m``: the same polygon, its edges short enough to read as they are."""
    pieces = np.ceil(np.sqrt(np.maximum(bows, 0.0) / tolerance_m))
    pieces = np.clip(np.nan_to_num(pieces, nan=1.0), 1, MAX_PIECES).astype(int)
    nxt = np.roll(pts, -1, axis=0)
    out = []
    for a, b, k in zip(pts, nxt, pieces.tolist()):
        t = np.arange(k)[:, None] / k
        out.append(a + (b - a) * t)
    return np.concatenate(out)


def _pushed(frame, pts, bows, tolerance_m, rounds):
    """``pts`` with every bowing edge moved right until its reading clears its original
    line (a hairpin bevelled: one vertex more), or None when that fails (moved edges cross,
    or it does not settle)."""
    push = np.where(bows > tolerance_m, bows + 1e-3, 0.0)
    for _ in range(rounds):
        ring, push, edge_of = _shifted_ring(pts, push)
        along = edge_of >= 0  # a bevel's own edge is a few pushes long: it does not bow
        now = left_bows(frame, ring)[along]
        short = now > push[edge_of[along]] + 1e-4
        if not short.any():
            return _valid(ring, pts)
        need = np.zeros(len(pts))
        np.maximum.at(need, edge_of[along][short], now[short] + 1e-3)
        # a moved edge grows, and bows more: move it half as far again as it falls short
        push = np.where(need > push, push + 1.5 * (need - push), push)
    return None


def _valid(ring, pts):
    """``ring`` if it is a simple ring; where moved edges cross (a narrow inlet closing), the
    outline of what it encloses, if that still covers ``pts``' polygon; else None."""
    if not np.isfinite(ring).all():  # lines that met nearly parallel, beyond any number
        return None
    poly = shapely.Polygon(ring)
    if poly.is_valid:
        return ring
    parts = [p for p in shapely.get_parts(shapely.make_valid(poly)) if p.geom_type == "Polygon"]
    if not parts:
        return None
    whole = shapely.union_all(parts)
    if whole.geom_type != "Polygon":
        return None
    outline = shapely.Polygon(whole.exterior)
    if not outline.covers(shapely.Polygon(pts)):
        return None
    out = np.asarray(outline.exterior.coords)[:-1]
    return out if shapely.LinearRing(out).is_ccw == shapely.LinearRing(pts).is_ccw else out[::-1]


def _split(pts, bows, tolerance_m, parts=4):
    """``pts`` with each edge bowing more than ``tolerance_m`` cut into ``parts`` along its
    chord (each piece then bows about ``parts**2`` times less)."""
    k = np.where(bows > tolerance_m, parts, 1)
    nxt = np.roll(pts, -1, axis=0)
    return np.concatenate([a + (b - a) * (np.arange(n)[:, None] / n)
                           for a, b, n in zip(pts, nxt, k.tolist())])  # fmt: skip


def hold_ring(frame, pts, tolerance_m=READ_TOLERANCE_M, rounds=40):
    """A metric ring whose lon/lat reading stays right of where ``pts``' edges are.

    Each edge is moved right (away from the area on its left) by the bow of its lon/lat
    reading, the lines' meeting points become the vertices, and the bows of the new edges are
    measured again until every edge's reading clears its original line. When that fails (a
    narrow part where moved edges cross), the bowing edges are cut in four along their
    chords and moved again, up to three times; then they are cut until each piece bows at most
    ``tolerance_m``: the same polygon with more vertices.

    Parameters
    ----------
    frame : LocalFrame
    pts : ndarray, shape (n, 2)
        The ring (not closed), the area it protects on its left (a counter-clockwise
        exterior, for an outward hold).
    tolerance_m : float
        Bows up to this are left as they are.
    rounds : int
        Measurements of the moved edges before giving up on a set of edges.

    Returns
    -------
    ndarray, shape (m, 2)
        The ring, not closed; ``pts`` itself when no edge bows more than ``tolerance_m``.
    """
    bows = left_bows(frame, pts)
    if not (bows > tolerance_m).any():
        return pts
    first, first_bows = pts, bows
    with np.errstate(all="ignore"):
        for _ in range(4):
            ring = _pushed(frame, pts, bows, tolerance_m, rounds)
            if ring is not None:
                return ring
            pts = _split(pts, bows, tolerance_m)
            bows = left_bows(frame, pts)
        if not (np.isfinite(pts).all() and np.isfinite(bows).all()):
            pts, bows = first, first_bows
    return _densified_on_chords(frame, pts, bows, tolerance_m)


def hold_as_read(geom, frame, outward=True, tolerance_m=READ_TOLERANCE_M):
    """A metric polygon whose lon/lat reading contains ``geom`` (``outward``) or lies inside
    it, to within ``tolerance_m``.

    Every ring is held with :func:`hold_ring`, the polygon's inside on the protected side:
    outward, the exterior moves out and holes shrink; inward, the exterior moves in.

    Parameters
    ----------
    geom : shapely.Polygon or shapely.MultiPolygon
        Metres in ``frame``.
    frame : LocalFrame
    outward : bool
    tolerance_m : float

    Returns
    -------
    shapely geometry
        ``geom`` itself when no edge bows more than ``tolerance_m``.

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> from alphafence.geo.lonlat import as_read
    >>> frame = LocalFrame(10.5, 64.0)
    >>> x, y = frame.to_local(np.array([10.0, 11.0]), np.array([63.9, 64.0]))
    >>> strip = shapely.box(x[0], y[0], x[1], y[1])
    >>> held = hold_as_read(strip, frame)
    >>> read = as_read(frame.geom_to_wgs84(held), frame)
    >>> round(strip.difference(read).area, 6)  # the strip as read from its held vertices
    0.0
    >>> round(strip.difference(as_read(frame.geom_to_wgs84(strip), frame)).area / 1e6, 2)
    3.15
    """
    if geom.is_empty or shapely.get_type_id(geom) not in (3, 6):
        return geom
    sign = 1.0 if outward else -1.0
    parts, changed = [], False
    for poly in shapely.get_parts(geom).tolist():
        poly = orient(poly, sign)
        rings = [poly.exterior, *poly.interiors]
        held = []
        for ring in rings:
            pts = ring_coords(np.asarray(ring.coords)[:, :2])  # no repeated vertices
            out = hold_ring(frame, pts, tolerance_m) if len(pts) >= 3 else pts
            changed |= out is not pts
            held.append(out)
        parts.append(shapely.Polygon(held[0], held[1:]) if changed else poly)
    if not changed:
        return geom
    if len(parts) == 1:
        return parts[0]
    multi = shapely.MultiPolygon(parts)
    return multi if multi.is_valid else shapely.union_all(parts)
