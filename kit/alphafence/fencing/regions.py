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
CHUNK = 16_384  # extents per R-tree when regions are found (a few MB of GEOS boxes)


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


def region_labels(bounds, widths, join_m, classes=None, chunk=CHUNK):
    """Conservative clusters of features, from their extents alone.

    Each extent (degrees) is grown by the join distance, twice the feature's width and a metre;
    features of one class whose grown extents meet, directly or through others, share a region.
    A site never spans two regions, so regions can be fenced apart (in tiles, in worker
    processes) and give exactly the sites :func:`group_sites` gives.

    The extents are swept south to north ``chunk`` at a time (an R-tree over each chunk, asked
    by the chunk and by the extents that start before the chunk's northernmost edge ends), and
    the pairs found are joined as they come, so memory holds a few arrays of one number per
    feature and one chunk's boxes, whatever the number of features.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
        ``minlon, minlat, maxlon, maxlat`` per feature.
    widths : ndarray, shape (n,)
        Metres each feature is widened by (points and lines), else 0.
    join_m : float
    classes : ndarray of int, shape (n,), optional
        Features of different classes never share a region (default: one class).
    chunk : int
        Extents per R-tree.

    Returns
    -------
    ndarray of int
        A region label per feature, numbered in the order of each region's first feature.

    Examples
    --------
    >>> import numpy as np
    >>> b = np.array([[14.5, 35.9, 14.5005, 35.9004], [14.5007, 35.9, 14.5012, 35.9004],
    ...               [14.51, 35.9, 14.5105, 35.9004]])
    >>> region_labels(b, np.zeros(3), 25.0).tolist()
    [0, 0, 1]
    >>> region_labels(b, np.zeros(3), 25.0, classes=np.array([1, 0, 1])).tolist()
    [0, 1, 2]
    """
    bounds = floats(bounds).reshape(-1, 4)
    n = len(bounds)
    if n <= 1:
        return np.zeros(n, np.int32)
    widths = np.broadcast_to(floats(widths), (n,))
    classes = np.zeros(n, np.int64) if classes is None else np.asarray(classes)
    index = np.int32 if n < 2**31 else np.int64  # one number per feature, as small as it goes
    # each grown extent's south edge, as grown_bounds grows it, rounded down to 32 bits: an
    # extent that starts at or south of a chunk's northernmost edge still does
    south = outward(bounds[:, 1] - _grow_m(widths, join_m) / M_PER_DEG_LAT, up=False)
    order = np.argsort(south, kind="stable").astype(index)
    south = south[order]
    roots = np.arange(n, dtype=index)  # a union-find: parent per feature, roots least of theirs
    for start in range(0, n, chunk):
        here = order[start : start + chunk]
        grown = grown_bounds(bounds[here], widths[here], join_m)
        boxes = shapely.box(*grown.T)
        tree = shapely.STRtree(boxes)
        a, b = tree.query(boxes, predicate="intersects")
        _join(roots, here[a], here[b], classes)
        end = _reach(south, grown[:, 3].max())
        for later in range(start + chunk, end, chunk):  # extents starting inside the chunk
            there = order[later : min(later + chunk, end)]
            g = grown_bounds(bounds[there], widths[there], join_m)
            a, b = tree.query(shapely.box(*g.T), predicate="intersects")
            _join(roots, there[a], here[b], classes)
    del order, south
    while True:  # every feature points at its root
        up = roots[roots]
        if np.array_equal(up, roots):
            break
        roots = up
    first = roots == np.arange(n, dtype=index)  # a region's root is its first feature
    return (np.cumsum(first, dtype=index) - 1)[roots]


def _reach(south, north):
    """How many of the extents, sorted by their south edges, start at or south of ``north``."""
    return int(np.searchsorted(south, north, side="right"))


def _find(roots, nodes):
    """Each node's root, the paths on the way made to point at it."""
    r = roots[nodes]
    while True:
        up = roots[r]
        if np.array_equal(up, r):
            roots[nodes] = r
            return r
        r = up


def _join(roots, a, b, classes):
    """Join the sets of the pairs ``a``-``b`` of one class; each set's root stays its least
    member."""
    same = (a != b) & (classes[a] == classes[b])
    if not same.any():
        return
    ra, rb = _find(roots, a[same]), _find(roots, b[same])
    apart = ra != rb
    if not apart.any():
        return
    nodes, inverse = np.unique(np.r_[ra[apart], rb[apart]], return_inverse=True)
    m = int(apart.sum())
    labels = _components(len(nodes), inverse[:m], inverse[m:])
    least = np.full(int(labels.max()) + 1, len(roots))
    np.minimum.at(least, labels, nodes)
    roots[nodes] = least[labels]


def floats(values):
    """``values`` as an array of 32- or 64-bit floats (not copied when it is one)."""
    values = np.asarray(values)
    return values if values.dtype in (np.float32, np.float64) else values.astype(float)


def outward(values, up):
    """64-bit floats as 32-bit ones rounded away from what they bound: up (``up``) or down.

    Extents and widths kept this way take half the memory and still hold what they held:
    regions found from them are the exact ones or joins of them, never splits.

    Examples
    --------
    >>> x = np.array([14.5000001, -0.1, 20.0])
    >>> bool(np.all(outward(x, up=True) >= x)), bool(np.all(outward(x, up=False) <= x))
    (True, True)
    >>> outward(x, up=True).dtype, float(outward(x, up=True)[2])
    (dtype('float32'), 20.0)
    """
    values = np.asarray(values, dtype=float)
    out = values.astype(np.float32)
    past = out < values if up else out > values
    out[past] = np.nextafter(out[past], np.float32(np.inf if up else -np.inf))
    return out


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
    grow_m = _grow_m(widths, join_m)
    dlat = grow_m / M_PER_DEG_LAT
    dlon = grow_m / (M_PER_DEG_LON * np.cos(np.radians(lat)))
    return np.column_stack(
        [bounds[:, 0] - dlon, bounds[:, 1] - dlat, bounds[:, 2] + dlon, bounds[:, 3] + dlat]
    )


def _grow_m(widths, join_m):
    """Metres each extent grows by: the join distance, twice the width and a metre."""
    return join_m + 2 * np.asarray(widths, dtype=float) + 1.0
