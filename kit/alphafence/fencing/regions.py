"""Conservative regions: features of one class whose extents, grown by the join distance,
meet, directly or through others. A site never spans two regions, so regions can be grouped
into sites apart (in tiles, in worker processes) and give exactly the untiled build's sites.
"""

from __future__ import annotations

import numpy as np
import shapely

M_PER_DEG_LAT = 110_574.0
M_PER_DEG_LON = 111_320.0
# components of graphs this small are found without scipy: a country's regions have a few
# hundred features at most, and importing scipy.sparse.csgraph costs more (0.15 s) than
# Malta's whole grouping
SMALL_GRAPH = 4096


def _components(n, a, b):
    """Connected-component labels of n nodes joined by edges a-b, numbered in the order of
    each component's smallest node (as scipy numbers them)."""
    if n <= SMALL_GRAPH:  # each round at least halves a path's span: a few dozen rounds
        labels = np.arange(n)
        while True:  # every node takes its neighbours' least label, then its label's label
            new = labels.copy()
            np.minimum.at(new, a, labels[b])
            np.minimum.at(new, b, labels[a])
            new = new[new]
            if np.array_equal(new, labels):
                return np.unique(labels, return_inverse=True)[1]
            labels = new
    from scipy.sparse import coo_array  # scipy (the build extra), imported where it is used
    from scipy.sparse.csgraph import connected_components

    graph = coo_array((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def region_labels(bounds, widths, join_m):
    """Conservative clusters of features of one class, from their extents alone.

    Each extent (degrees) is grown by the join distance, twice the feature's width and a metre;
    features whose grown extents meet, directly or through others, share a region. A site never
    spans two regions, so regions can be fenced apart (in tiles, in worker processes) and give
    exactly the sites :func:`group_sites` gives.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
        ``minlon, minlat, maxlon, maxlat`` per feature.
    widths : ndarray, shape (n,)
        Metres each feature is widened by (points and lines), else 0.
    join_m : float

    Returns
    -------
    ndarray of int
        A region label per feature.

    Examples
    --------
    >>> import numpy as np
    >>> b = np.array([[14.5, 35.9, 14.5005, 35.9004], [14.5007, 35.9, 14.5012, 35.9004],
    ...               [14.51, 35.9, 14.5105, 35.9004]])
    >>> region_labels(b, np.zeros(3), 25.0).tolist()
    [0, 0, 1]
    """
    bounds = np.asarray(bounds, dtype=float).reshape(-1, 4)
    if len(bounds) == 1:
        return np.zeros(1, int)
    grown = grown_bounds(bounds, widths, join_m)
    boxes = shapely.box(grown[:, 0], grown[:, 1], grown[:, 2], grown[:, 3])
    tree = shapely.STRtree(boxes)
    a, b = tree.query(boxes, predicate="intersects")
    return _components(len(bounds), a, b)


def grown_bounds(bounds, widths, join_m):
    """Each extent grown as :func:`region_labels` grows it: by the join distance, twice the
    feature's width and a metre, in degrees at the extent's farthest latitude. Two features
    of one class share a region when their grown extents meet (edges included), directly or
    through others; an update finds a region's members by the same test.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
        ``minlon, minlat, maxlon, maxlat`` per feature.
    widths : ndarray, shape (n,)
    join_m : float

    Returns
    -------
    ndarray, shape (n, 4)

    Examples
    --------
    >>> import numpy as np
    >>> g = grown_bounds(np.array([[0.0, 0.0, 0.001, 0.001]]), np.zeros(1), 25.0)
    >>> round(float(g[0, 0]) * M_PER_DEG_LON, 6), round(float(g[0, 3] - 0.001) * M_PER_DEG_LAT, 6)
    (-26.0, 26.0)
    """
    bounds = np.asarray(bounds, dtype=float).reshape(-1, 4)
    lat = np.clip(np.maximum(np.abs(bounds[:, 1]), np.abs(bounds[:, 3])), 0, 89.9)
    grow_m = join_m + 2 * np.asarray(widths, dtype=float) + 1.0
    dlat = grow_m / M_PER_DEG_LAT
    dlon = grow_m / (M_PER_DEG_LON * np.cos(np.radians(lat)))
    return np.column_stack(
        [bounds[:, 0] - dlon, bounds[:, 1] - dlat, bounds[:, 2] + dlon, bounds[:, 3] + dlat]
    )
