"""Rings as (n, 2) arrays of vertices (not closed): their vertices without repeats, signed
area, validity and containment, as the simplifiers check them."""

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
