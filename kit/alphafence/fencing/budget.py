"""Outward simplification of fences within a vertex budget and, when the user bounds it, an
overshoot: no point of a simplified fence farther than ``max_overshoot_m`` from the shape
its method drew (the alpha shape, the convex hull)."""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.geo.alpha import fill_holes, outer_polygons
from alphafence.geo.outward_many import simplify_polygons


def _array(geoms):
    arr = np.empty(len(geoms), dtype=object)
    arr[:] = geoms
    return arr


def simplify_parts(geoms, opts):
    """Each geometry's polygons simplified outward (all of them in one pass), a geometry of
    several united again with their holes filled; with ``opts.max_overshoot_m``, a fence
    reaching farther than that beyond its geometry is simplified again with twice the
    vertices, until it does not (or it keeps every vertex of its geometry).

    Parameters
    ----------
    geoms : sequence of shapely geometry
        Metres.
    opts : FenceOptions

    Returns
    -------
    list of shapely geometry
    """
    geoms = _array(geoms)
    out = _simplified(geoms, opts.max_vertices, opts.tolerance_m)
    bound = getattr(opts, "max_overshoot_m", None)
    if bound is None or not len(geoms):
        return out
    budget = np.full(len(geoms), int(opts.max_vertices))
    most = shapely.get_num_coordinates(geoms)
    for _ in range(32):
        far = [
            i
            for i in range(len(geoms))
            if budget[i] < most[i] and not shapely.buffer(geoms[i], bound).covers(out[i])
        ]
        if not far:
            break
        for i in far:
            budget[i] = min(2 * budget[i], most[i])
            out[i] = _simplified(geoms[[i]], int(budget[i]), opts.tolerance_m)[0]
    return out


def _simplified(geoms, max_vertices, tolerance_m):
    """:func:`simplify_parts` of ``geoms`` (an object array) at one vertex budget."""
    plain = plain_polygons(geoms)
    if plain.all():  # each geometry is its one polygon
        return list(simplify_polygons(geoms, max_vertices, tolerance_m, outward=True))
    polys = [[g] if one else outer_polygons(g) for g, one in zip(geoms.tolist(), plain.tolist())]
    flat = simplify_polygons(
        [p for ps in polys for p in ps], max_vertices, tolerance_m, outward=True
    )
    out, at = [], 0
    for ps in polys:
        parts, at = flat[at : at + len(ps)], at + len(ps)
        out.append(parts[0] if len(parts) == 1 else fill_holes(shapely.union_all(parts)))
    return out


def plain_polygons(geoms):
    """Which of ``geoms`` are non-empty polygons without holes (their own
    :func:`outer_polygons`), for all of them at once."""
    return (
        (shapely.get_type_id(geoms) == 3)
        & ~shapely.is_empty(geoms)
        & (shapely.get_num_interior_rings(geoms) == 0)
    )
