"""Fences as ArduPilot fence items (MAV_CMD_NAV_FENCE_*), the one model behind the .plan
and waypoint writers (and, later, the uploader)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.vehicle_distance import vehicle_radius
from alphafence.mavlink import ids

# short names for the fence item commands (the numbers live in mavlink.ids)
POLYGON_INCLUSION = ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
POLYGON_EXCLUSION = ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRCLE_INCLUSION = ids.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
CIRCLE_EXCLUSION = ids.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
RETURN_POINT = ids.MAV_CMD_NAV_FENCE_RETURN_POINT
MAX_POLYGON_VERTICES = 255  # ArduPilot's limit for one polygon (a uint8 count)


@dataclass(frozen=True)
class FenceItem:
    command: int
    param1: float  # vertex count (polygons) or radius in metres (circles)
    lon: float
    lat: float


def polygon_lonlat(poly) -> np.ndarray:
    """Exterior vertices (lon, lat), without the closing repeat, counter-clockwise."""
    ring = poly.exterior
    if not ring.is_ccw:
        ring = shapely.LinearRing(list(ring.coords)[::-1])
    return np.asarray(ring.coords)[:-1, :2]


def item_count(fence) -> int:
    """How many items :func:`fence_items` makes of one fence, without making them: a circle is
    one, a polygon one per exterior vertex of each part, a warning layer none.

    The vertices are counted on the fence's metric geometry (``local``) when it has one: the
    same vertices as its WGS84 geometry, without transforming them.
    """
    if fence.kind not in ("keep_out", "keep_in"):
        return 0
    if fence.circle is not None:
        return 1
    geom = getattr(fence, "local", None)
    if geom is None:
        geom = fence.geometry
    rings = shapely.get_exterior_ring(shapely.get_parts(geom))
    return int((shapely.get_num_coordinates(rings) - 1).sum())


def item_counts(fences) -> list:
    """:func:`item_count` of each fence, the same numbers, the vertices of all of them counted
    at once (:func:`exterior_vertices`).

    Examples
    --------
    >>> from types import SimpleNamespace as Fence
    >>> box = shapely.box(0, 0, 10, 10)
    >>> item_counts([Fence(kind="keep_out", circle=None, local=box),
    ...              Fence(kind="keep_in", circle=(0, 0, 5), local=box),
    ...              Fence(kind="warning", circle=None, local=box)])
    [4, 1, 0]
    """
    fences = list(fences)
    geoms = [getattr(f, "local", None) for f in fences]
    geoms = [f.geometry if g is None else g for f, g in zip(fences, geoms)]
    vertices = exterior_vertices(geoms).tolist()
    return [
        (0 if f.kind not in ("keep_out", "keep_in") else 1 if f.circle is not None else n)
        for f, n in zip(fences, vertices)
    ]


def exterior_vertices(geoms) -> np.ndarray:
    """Per geometry, the vertices of its parts' exterior rings without their closing repeats
    (what :func:`item_count` counts of a polygon fence), vectorised.

    Parameters
    ----------
    geoms : sequence of shapely geometries

    Returns
    -------
    numpy.ndarray of int64

    Examples
    --------
    >>> exterior_vertices([shapely.box(0, 0, 1, 1), shapely.MultiPolygon()]).tolist()
    [4, 0]
    """
    array = np.empty(len(geoms), dtype=object)
    array[:] = list(geoms)
    out = shapely.get_num_coordinates(array) - 1  # a polygon without holes (an empty one: -1)
    other = (shapely.get_type_id(array) != 3) | (shapely.get_num_interior_rings(array) > 0)
    if other.any():  # parts and rings copied out only for these
        at = np.flatnonzero(other)
        parts, owner = shapely.get_parts(array[at], return_index=True)
        counts = shapely.get_num_coordinates(shapely.get_exterior_ring(parts)) - 1
        out[at] = np.bincount(owner, weights=counts, minlength=len(at))
    return out.astype(np.int64)


def fence_items(fences):
    """Items for the fences a vehicle can hold: keep-out as exclusions, keep-in as
    inclusions. Warning layers have no onboard equivalent and are left to the companion.
    A circle's radius is the one ArduPilot's own distance needs
    (:func:`~alphafence.geo.vehicle_distance.vehicle_radius`)."""
    items = []
    for f in fences:
        if f.kind not in ("keep_out", "keep_in"):
            continue
        inclusion = f.kind == "keep_in"
        if f.circle is not None:
            lon, lat, r = f.circle_wgs84  # on the ground, the frame's scale allowed for
            r = vehicle_radius(lon, lat, r, not inclusion)
            items.append(
                FenceItem(CIRCLE_INCLUSION if inclusion else CIRCLE_EXCLUSION, r, lon, lat)
            )
            continue
        cmd = POLYGON_INCLUSION if inclusion else POLYGON_EXCLUSION
        for part in shapely.get_parts(f.geometry):
            pts = polygon_lonlat(part)
            items.extend(FenceItem(cmd, float(len(pts)), lon, lat) for lon, lat in pts)
    return items
