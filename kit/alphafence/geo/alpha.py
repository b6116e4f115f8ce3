"""Alpha shapes (Edelsbrunner) on a scipy Delaunay triangulation, with automatic alpha.

The fence of a site must contain the site's *required region* R (its restricted geometry
buffered by the margin). We triangulate the vertices of R's outer rings. A triangle whose
centroid lies inside R is part of the site (weight 0); any other triangle is added to the
shape once alpha (a radius, in metres) reaches its circumradius. Automatic alpha is the
smallest radius at which the kept triangles join every part of R into one component: the
bottleneck of the minimax paths between the site's parts, read off a minimum spanning tree
of the triangle adjacency graph. The shape is finally united with R, so it can never cut
into the site, whatever the triangulation did along R's boundary.
"""

from __future__ import annotations

import numpy as np
import shapely
import shapely.errors


def outer_polygons(geom):
    """Polygon parts of ``geom`` with their holes filled; other parts are left out.

    Returns
    -------
    ndarray of shapely.Polygon

    Examples
    --------
    >>> import shapely
    >>> holed = shapely.Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(2, 2), (4, 2), (4, 4)]])
    >>> outer_polygons(shapely.GeometryCollection([shapely.Point(0, 0), holed]))[0].area
    100.0
    >>> nested = shapely.GeometryCollection([shapely.MultiPolygon([holed]), shapely.Point(0, 0)])
    >>> [p.area for p in outer_polygons(nested)]  # a repaired zone's polygons, kept
    [100.0]
    """
    if type(geom) is shapely.Polygon and not geom.is_empty and not geom.interiors:
        out = np.empty(1, dtype=object)  # the common case, without four array calls
        out[0] = geom
        return out
    parts = shapely.get_parts(geom)
    while np.any(shapely.get_type_id(parts) >= 4):  # a collection's multi-parts, flattened
        parts = shapely.get_parts(parts)
    parts = parts[shapely.get_type_id(parts) == 3]
    return shapely.polygons(shapely.get_exterior_ring(parts))


def fill_holes(geom):
    """``geom``'s polygons without holes, as one geometry (a Polygon when there is one part).

    Examples
    --------
    >>> import shapely
    >>> holed = shapely.Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(2, 2), (4, 2), (4, 4)]])
    >>> fill_holes(holed).area
    100.0
    """
    polys = outer_polygons(geom)
    if len(polys) == 1:
        return polys[0]
    return shapely.union_all(polys)


def circumradii(pts, simplices):
    """Circumradius and twice the area of each triangle.

    Parameters
    ----------
    pts : ndarray, shape (n, 2)
    simplices : ndarray, shape (m, 3)
        Vertex indices of each triangle.

    Returns
    -------
    radius : ndarray, shape (m,)
        Infinite for degenerate (zero-area) triangles.
    area2 : ndarray, shape (m,)

    Examples
    --------
    >>> import numpy as np
    >>> circumradii(np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]]), np.array([[0, 1, 2]]))
    (array([2.5]), array([12.]))
    """
    a = pts[simplices[:, 0]]
    b = pts[simplices[:, 1]]
    c = pts[simplices[:, 2]]
    ab = np.hypot(*(b - a).T)
    bc = np.hypot(*(c - b).T)
    ca = np.hypot(*(a - c).T)
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    area2 = np.abs(cross)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(area2 > 0, ab * bc * ca / (2.0 * area2), np.inf)
    return r, area2


def _adjacency(neighbors):
    t = np.repeat(np.arange(len(neighbors)), 3)
    u = neighbors.ravel()
    ok = u > t  # each shared edge once; -1 (hull) dropped
    return t[ok], u[ok]


def bottleneck_alpha(neighbors, weight, terminal, links=None) -> float:
    """Smallest alpha at which all terminals are connected through triangles of
    weight <= alpha (minimax path bottleneck over the MST).

    Parameters
    ----------
    neighbors : ndarray, shape (m, 3)
        Delaunay neighbours of each triangle (-1 on the hull).
    weight : ndarray, shape (m,)
        Alpha at which each triangle joins the shape (0 for the site's own).
    terminal : ndarray of bool, shape (m,)
        The triangles that must end up connected.
    links : tuple of ndarray, optional
        ``(part, triangle)`` pairs: the triangles that join each part of the site (overlap
        it or share a stretch of its boundary). Then the parts, not ``terminal``, must end
        up connected, each through any triangle that joins it.

    Returns
    -------
    float
        0 with at most one terminal, inf when finite triangles cannot connect them.
    """
    m = len(weight)
    a, b = _adjacency(neighbors)
    if links is not None:
        part, tri = links
        n_parts = int(part.max()) + 1 if part.size else 0
        a = np.concatenate([a, m + part])
        b = np.concatenate([b, tri])
        weight = np.concatenate([weight, np.zeros(n_parts)])
        terminal = np.concatenate([np.zeros(m, bool), np.ones(n_parts, bool)])
    n = len(weight)
    term = np.flatnonzero(terminal)
    if term.size <= 1:
        return 0.0
    w = np.maximum(weight[a], weight[b])
    finite = np.isfinite(w)
    a, b, w = a[finite], b[finite], w[finite]
    # +1 so zero-weight edges survive the sparse representation
    from scipy.sparse import coo_array  # scipy (the build extra), imported where it is used
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    graph = coo_array((w + 1.0, (a, b)), shape=(n, n)).tocsr()
    mst = minimum_spanning_tree(graph)
    mst = mst + mst.T
    order, pred = breadth_first_order(mst, int(term[0]), directed=False, return_predecessors=True)
    has = terminal.copy()
    for v in order[:0:-1]:  # leaves first; skip the root
        if has[v]:
            has[pred[v]] = True
    child = order[1:][has[order[1:]]]
    if child.size == 0:
        return 0.0
    reached = np.isin(term, order)
    if not reached.all():
        return float("inf")  # parts not connected by finite triangles
    # an edge of the tree weighs what its heavier triangle weighs
    edge_w = np.maximum(weight[child], weight[pred[child]])
    return float(edge_w.max()) if edge_w.size else 0.0


def _overlaps(parts, triangles):
    """``(part, triangle)`` index pairs whose union is one polygon: their interiors meet, or
    their boundaries share a segment (a single shared point does not join them)."""
    t, p = shapely.STRtree(triangles).query(parts, predicate="intersects")[::-1]
    a, b = parts[p], triangles[t]
    meet = shapely.relate_pattern(a, b, "T********") | shapely.relate_pattern(a, b, "****1****")
    return p[meet], t[meet]


def alpha_shape(required, alpha: float | None = None):
    """Alpha shape enclosing ``required`` (metric coordinates).

    The result always covers ``required`` and has no holes.

    Parameters
    ----------
    required : shapely geometry
        The region the shape must contain (its polygon parts), metres.
    alpha : float, optional
        Radius in metres; None picks the smallest alpha that joins every part into one
        component.

    Returns
    -------
    shape : shapely geometry
        A Polygon, or a MultiPolygon when ``alpha`` is too small to join the parts.
    alpha : float
        The alpha used (0 for a single part, inf when the convex hull had to stand in).

    Examples
    --------
    >>> import shapely
    >>> two = shapely.union(shapely.box(0, 0, 10, 10), shapely.box(20, 0, 30, 10))
    >>> shape, alpha = alpha_shape(two)
    >>> shape.geom_type, round(alpha, 3), shape.area
    ('Polygon', 7.071, 300.0)
    >>> alpha_shape(two, 3.0)[0].geom_type
    'MultiPolygon'
    """
    polys = outer_polygons(required)
    region = polys[0] if len(polys) == 1 else shapely.union_all(polys)
    if len(shapely.get_parts(region)) == 1 and alpha is None:
        return region, 0.0
    pts = np.unique(
        shapely.get_coordinates(shapely.get_exterior_ring(shapely.get_parts(region))), axis=0
    )
    if len(pts) < 3:
        return region, 0.0
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import Delaunay, QhullError

    try:
        tri = Delaunay(pts)
    except QhullError:
        return shapely.convex_hull(region), float("inf")
    simplices = tri.simplices
    radius, area2 = circumradii(pts, simplices)
    # a triangle is the site's own only when the site covers it: the triangulation is not
    # constrained to the site's edges, so a triangle whose centroid lies in one part can
    # still bridge the gap to another
    triangles = shapely.polygons(pts[simplices])
    shapely.prepare(region)
    own = shapely.covered_by(triangles, region)
    weight = np.where(own, 0.0, radius)
    part_of, overlapping = _overlaps(np.asarray(shapely.get_parts(region)), triangles)
    if alpha is None:
        alpha = bottleneck_alpha(tri.neighbors, weight, own, links=(part_of, overlapping))
        if not np.isfinite(alpha):
            return shapely.convex_hull(region), alpha
    keep = weight <= alpha * (1.0 + 1e-9)
    # keep only the components that hold part of the site
    a, b = _adjacency(tri.neighbors)
    both = keep[a] & keep[b]
    n = len(simplices)
    graph = coo_array((np.ones(both.sum()), (a[both], b[both])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    touches = np.zeros(n, bool)
    touches[overlapping] = True
    site_labels = np.unique(labels[touches & keep])
    keep &= np.isin(labels, site_labels)
    keep &= area2 > 0
    shape = _union_triangles(pts[simplices[keep]])
    return fill_holes(shapely.union(shape, region)), float(alpha)


def _union_triangles(corners):
    """Union of triangles that tile a Delaunay triangulation: a coverage union (fast), or
    an ordinary union where near-collinear points leave the coverage incorrectly noded."""
    if not len(corners):
        return shapely.Polygon()
    tris = shapely.polygons(corners)
    try:
        return shapely.coverage_union_all(tris)
    except shapely.errors.GEOSException:
        return shapely.union_all(tris)


def alpha_shape_points(points, alpha: float):
    """The plain Edelsbrunner alpha shape of a point set: the union of the Delaunay
    triangles whose circumradius is at most ``alpha`` (metres). This is what the
    ``alphashape`` package computes (its parameter is 1 / alpha).

    Examples
    --------
    >>> square = [(0, 0), (1, 0), (0, 1), (1, 1), (10, 10)]
    >>> alpha_shape_points(square, 1.0).area
    1.0
    """
    pts = np.unique(np.asarray(points, float), axis=0)
    if len(pts) < 3:
        return shapely.Polygon()
    from scipy.spatial import Delaunay, QhullError

    try:
        tri = Delaunay(pts)
    except QhullError:
        return shapely.Polygon()
    radius, area2 = circumradii(pts, tri.simplices)
    keep = (radius <= alpha) & (area2 > 0)
    if not keep.any():
        return shapely.Polygon()
    return _union_triangles(pts[tri.simplices[keep]])
