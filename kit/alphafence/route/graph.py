"""The roadmap's graph: the Voronoi edges that run down the middle of every gap between
fences and stay clear of them, hugging rings just outside every fence, and the adjacency lists
A* walks.

:class:`~alphafence.route.roadmap.Roadmap` builds its graph with these; they read its public
attributes and predicates only.
"""

from __future__ import annotations

import threading

import numpy as np
import shapely


def heard_out(fn, *args):
    """``fn(*args)`` run in a worker thread while this one waits for it, so that Ctrl-C
    (``KeyboardInterrupt``, raised in the main thread only) is heard while a long C call runs
    that releases the GIL, as scipy's Qhull does for most of its work.

    Parameters
    ----------
    fn : callable
    *args
        Its arguments.

    Returns
    -------
    object
        What ``fn`` returns (what it raises is raised here).

    Examples
    --------
    >>> heard_out(sum, [1, 2, 3])
    6
    """
    out = {}
    done = threading.Event()

    def work():
        try:
            out["value"] = fn(*args)
        except BaseException as exc:  # handed to the waiting thread
            out["error"] = exc
        finally:
            done.set()

    # a daemon: when Ctrl-C stops the wait, the interpreter exits without waiting for it
    threading.Thread(target=work, name=getattr(fn, "__name__", "worker"), daemon=True).start()
    while not done.wait(0.05):
        pass
    if "error" in out:
        raise out["error"]
    return out["value"]


def voronoi_edges(roadmap, bounds=None):
    """The clear edges of the Voronoi diagram of points sampled along the fences.

    Points are sampled every ``roadmap.spacing`` metres along the keep-out boundaries (every
    twice that along warning layers) and along a frame around everything; Voronoi edges are
    kept where they lie inside the frame and are clear of every keep-out fence.

    Parameters
    ----------
    roadmap : Roadmap
        Its fences, clearance and spacing (and ``clear``).
    bounds : tuple, optional
        ``(x0, y0, x1, y1)`` the graph must also cover.

    Returns
    -------
    extent : ndarray
        ``(x0, y0, x1, y1)``: the fences and ``bounds``, padded.
    samples : ndarray, shape (m, 2)
        The points sampled.
    vertices : ndarray, shape (n, 2)
    edges : ndarray, shape (k, 2)
        Vertex index pairs.

    Raises
    ------
    ValueError
        When the samples are degenerate (e.g. all collinear).
    """
    s = roadmap.spacing
    if roadmap.keep_out.size:
        fb = np.asarray(shapely.total_bounds(roadmap.keep_out), float)
    else:
        fb = np.array([-1.0, -1.0, 1.0, 1.0])
    if bounds is not None:
        b = np.asarray(bounds, float)
        fb = np.array([min(fb[0], b[0]), min(fb[1], b[1]), max(fb[2], b[2]), max(fb[3], b[3])])
    # the pad grows with the extent (1/200 of its longer side) so the frame keeps at most about
    # 3,200 samples however far the fences spread; a frame sample spacing of a quarter of the
    # pad keeps the cells of fence samples inside the frame
    pad = max(4.0 * roadmap.ce, 200.0, float(np.max(fb[2:] - fb[:2])) / 200.0)
    extent = fb + np.array([-pad, -pad, pad, pad])
    x0, y0, x1, y1 = extent
    frame = shapely.segmentize(shapely.box(x0, y0, x1, y1).exterior, max(4.0 * s, pad / 4))
    pts = [shapely.get_coordinates(frame)]
    if roadmap.keep_out.size:
        rings = shapely.boundary(roadmap.keep_out)
        pts.append(shapely.get_coordinates(shapely.segmentize(rings, s)))
    if roadmap.warning.size:  # so that the roadmap also has ways around warning layers
        rings = shapely.boundary(roadmap.warning)
        pts.append(shapely.get_coordinates(shapely.segmentize(rings, 2.0 * s)))
    pts = np.unique(np.round(np.concatenate(pts), 6), axis=0)
    from scipy.spatial import QhullError, Voronoi  # scipy (the build extra), used here only

    try:
        vor = heard_out(Voronoi, pts)
    except QhullError as exc:  # degenerate input, e.g. all samples collinear
        raise ValueError(f"cannot build the roadmap ({exc})") from None
    rv = np.asarray(vor.ridge_vertices)
    rv = rv[(rv >= 0).all(axis=1)]
    rv = np.sort(rv, axis=1)
    rv = np.unique(rv, axis=0)
    V = vor.vertices
    inside = (V[:, 0] >= x0) & (V[:, 0] <= x1) & (V[:, 1] >= y0) & (V[:, 1] <= y1)
    rv = rv[inside[rv].all(axis=1)]
    rv = rv[rv[:, 0] != rv[:, 1]]
    ok = roadmap.clear(V[rv[:, 0]], V[rv[:, 1]])
    rv = rv[ok]
    used, inv = np.unique(rv, return_inverse=True)
    V = V[used]
    edges = inv.reshape(-1, 2)
    return extent, pts, V, edges


def add_rings(roadmap, V, edges, k=4):
    """Hugging ways: rings just outside the clearance of every keep-out fence and outside
    every warning layer, joined to the Voronoi edges. Without them the only ways round a
    fence in open space run down the far-away medial axis, which misprices them.

    Parameters
    ----------
    roadmap : Roadmap
        Its fences, clearance and spacing (and ``clear``).
    V : ndarray, shape (n, 2)
        The Voronoi vertices.
    edges : ndarray, shape (k, 2)
        The Voronoi edges.
    k : int
        Each ring vertex links to at most this many nearest Voronoi vertices it sees.

    Returns
    -------
    vertices : ndarray
        ``V`` followed by the ring vertices.
    edges : ndarray
        Every clear edge, each once.
    """
    polys = [g for g in (*roadmap.keep_out, *roadmap.warning)]
    if not polys:
        return V, edges
    r = np.concatenate(
        [
            np.full(len(roadmap.keep_out), 1.25 * roadmap.ce + 1.0),
            np.full(len(roadmap.warning), 1.0),
        ]
    )
    rings = shapely.boundary(
        shapely.simplify(shapely.buffer(np.array(polys, dtype=object), r, quad_segs=2), 0.5)
    )
    rings = shapely.segmentize(rings, 4.0 * roadmap.spacing)
    new_v, new_e = [], []
    base = len(V)
    for line in shapely.get_parts(rings):
        c = np.asarray(line.coords)
        if len(c) < 3:
            continue
        c = c[:-1] if np.allclose(c[0], c[-1]) else c
        m = len(c)
        idx = base + np.arange(m)
        new_v.append(c)
        new_e.append(np.column_stack([idx, np.roll(idx, -1)]))
        base += m
    if not new_v:
        return V, edges
    R = np.concatenate(new_v)
    RE = np.concatenate(new_e)
    RE = RE[roadmap.clear(np.vstack([V, R])[RE[:, 0]], np.vstack([V, R])[RE[:, 1]])]
    allv = np.vstack([V, R])
    links = np.zeros((0, 2), int)
    if len(V):  # each ring vertex to its nearest visible Voronoi vertices
        from scipy.spatial import cKDTree

        kk = min(k, len(V))
        _, nn = cKDTree(V).query(R, k=kk)
        src = np.repeat(np.arange(len(V), len(allv)), kk)
        dst = np.asarray(nn).reshape(-1)
        ok = roadmap.clear(allv[src], allv[dst])
        links = np.column_stack([src[ok], dst[ok]])
    E = np.vstack([edges, RE, links])
    E = np.unique(np.sort(E, axis=1), axis=0)
    E = E[E[:, 0] != E[:, 1]]
    return allv, E


def adjacency_lists(n, edges, w):
    """Adjacency lists of an undirected graph, as A* walks them.

    Parameters
    ----------
    n : int
        Vertices.
    edges : ndarray, shape (k, 2)
        Vertex index pairs.
    w : ndarray, shape (k,)
        Edge costs.

    Returns
    -------
    tuple of list
        ``(indptr, neighbour, cost)``: the edges of vertex ``v`` are
        ``neighbour[indptr[v]:indptr[v + 1]]``, costing ``cost[...]``.

    Examples
    --------
    >>> import numpy as np
    >>> adjacency_lists(3, np.array([[0, 1], [1, 2]]), np.array([5.0, 7.0]))
    ([0, 1, 3, 4], [1, 2, 0, 1], [5.0, 7.0, 5.0, 7.0])
    """
    src = np.concatenate([edges[:, 0], edges[:, 1]])
    dst = np.concatenate([edges[:, 1], edges[:, 0]])
    ww = np.concatenate([w, w])
    order = np.argsort(src, kind="stable")
    indptr = np.searchsorted(src[order], np.arange(n + 1)).tolist()
    return indptr, dst[order].tolist(), ww[order].tolist()
