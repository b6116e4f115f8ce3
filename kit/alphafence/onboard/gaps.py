"""Several keep-in areas for an autopilot that reads inclusions as their intersection.

PX4 always, and ArduPilot without FENCE_OPTIONS' union bit, read two inclusions as "stay
inside both": two separate keep-in areas would leave the vehicle nowhere to fly. Their union
can still be written exactly under that rule: one inclusion around all of them (their convex
hull, stored outward) and an exclusion for each gap between them (the stored hull less the
areas, stored outward too). The vehicle is then allowed in ``hull - gaps``, which lies inside
the areas' union whatever the compiler does next: a gap simplified, circled or merged only
grows, and forbids more (:func:`gap_pieces`).
"""

from __future__ import annotations

import shapely

from alphafence.errors import InputError
from alphafence.geo.alpha import outer_polygons
from alphafence.mavlink.storage import polygon_bytes
from alphafence.onboard.options import PAD_M, Option, Piece, piece_options

HULL_VERTICES = 16  # the hull inclusion is simplified outward to at most this many vertices
OPEN_M = 1e-3  # the areas are opened by this much before their gaps are taken
GAP_ID = "keep-in-gap"  # the sources of a gap exclusion: what it stands for, in tables


def without_holes(geom, max_cuts=64):
    """``geom``'s polygons cut into parts without holes (a fence polygon has none): each
    hole is cut through by a vertical line at its centroid, until none is left.

    Examples
    --------
    >>> frame = shapely.box(0, 0, 10, 10).difference(shapely.box(4, 4, 6, 6))
    >>> parts = without_holes(frame)
    >>> len(parts), all(len(p.interiors) == 0 for p in parts), round(sum(p.area for p in parts))
    (2, True, 96)
    """
    todo = [p for p in shapely.get_parts(geom) if p.geom_type == "Polygon" and p.area > 0]
    out = []
    for _ in range(max_cuts):
        if not todo:
            break
        poly = todo.pop()
        if not len(poly.interiors):
            out.append(poly)
            continue
        x = shapely.Polygon(poly.interiors[0]).centroid.x
        (x0, y0, x1, y1) = poly.bounds
        left = shapely.intersection(poly, shapely.box(x0 - 1, y0 - 1, x, y1 + 1))
        right = shapely.intersection(poly, shapely.box(x, y0 - 1, x1 + 1, y1 + 1))
        for half in (left, right):
            todo.extend(
                p for p in shapely.get_parts(half) if p.geom_type == "Polygon" and p.area > 0
            )
    out.extend(todo)  # not reached for fence-sized shapes
    return out


def gap_pieces(keep_in, max_vertices: int, frame):
    """The hull inclusion and the gap exclusions that stand for several keep-in pieces.

    Parameters
    ----------
    keep_in : list of Piece
        The keep-in pieces (inward, metric), two or more.
    max_vertices : int
        Most vertices of one polygon the vehicle accepts.
    frame : LocalFrame
        The pieces' frame: the hull is emitted in it, and its gaps taken from what its
        items allow as the vehicle reads them (its lon/lat edges bow out of its metric ones).

    Returns
    -------
    hull : Piece
        One inclusion, stored outward (it holds every area).
    gaps : list of Piece
        Keep-out pieces, one a gap: together with ``hull`` they allow no point outside
        every area.
    union : shapely geometry
        What the areas allow (metric), for the loss model and the checks.
    """
    union = shapely.union_all([p.local for p in keep_in])
    hull = shapely.convex_hull(union)
    opts = [o for o in piece_options(hull, False, max_vertices) if o.kind == "polygon"]
    few = [o for o in opts if o.items <= HULL_VERTICES] or opts[:1]
    stored = min(few, key=lambda o: o.loss).local  # outward: it holds the hull
    sources = [s for p in keep_in for s in p.sources]
    n = len(stored.exterior.coords) - 1
    hull_piece = Piece(sources, True, stored, [Option("polygon", n, polygon_bytes(n), 0.0, stored)],
                       outward=True)  # fmt: skip
    # the gaps: what the hull's items allow beyond the areas, each stored outward (holding it)
    from alphafence.onboard.emit import emit_items

    ring = [(i.lon, i.lat) for i in emit_items([hull_piece], frame)]
    read = frame.read_geom(shapely.Polygon(ring))
    # a spike of no width along an area's edge is no area: the vehicle reads a point on it as
    # outside, so the areas are opened by a millimetre first and the spike falls in a gap
    opened = shapely.buffer(shapely.buffer(union, -OPEN_M, join_style="mitre"), OPEN_M,
                            join_style="mitre")  # fmt: skip
    gap = shapely.difference(shapely.union(read, stored), opened)
    gaps = []
    for k, part in enumerate(without_holes(gap)):
        if part.area < 1e-6:
            continue
        options = piece_options(part, False, max_vertices)
        if not options:  # a sliver too thin to simplify: its padded self, stored as that
            part = outer_polygons(shapely.buffer(part, PAD_M, join_style="mitre"))[0]
            options = piece_options(part, False, max_vertices)
        if not options:
            raise InputError("compile", "a gap between keep-in areas cannot be stored: "
                             "keep one keep-in area")  # fmt: skip
        gaps.append(Piece([f"{GAP_ID}/{k + 1}"], False, part, options))
    return hull_piece, gaps, union
