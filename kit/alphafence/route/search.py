"""Searching a roadmap: A* over its graph, and, when no route exists, why.

The roadmap (:class:`~alphafence.route.roadmap.Roadmap`) builds the graph and calls these; they
read its public attributes only.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import shapely


def astar(vertices, adjacency, src, dst, goal, direct=None):
    """A* from the start's links to the goal's over the roadmap graph.

    The heuristic is the straight-line distance to the goal, admissible because every edge
    costs at least its length.

    Parameters
    ----------
    vertices : ndarray, shape (n, 2)
        The roadmap's vertices, metres.
    adjacency : tuple of list
        ``(indptr, neighbour, cost)``: the edges of vertex ``v`` are
        ``neighbour[indptr[v]:indptr[v + 1]]``, costing ``cost[...]``.
    src : list of tuple
        ``(vertex, cost)`` links from the start.
    dst : dict
        ``{vertex: cost}`` links to the goal.
    goal : array_like, shape (2,)
        The goal, metres.
    direct : float, optional
        The cost of flying straight from start to goal, when that is clear.

    Returns
    -------
    path : list of int or None
        The roadmap vertices between start and goal (empty: fly straight); None when the
        goal cannot be reached.
    expanded : int
        Vertices expanded.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0.0], [10.0, 0.0]])
    >>> adjacency = ([0, 1, 2], [1, 0], [10.0, 10.0])  # one edge, 0 - 1
    >>> astar(V, adjacency, [(0, 1.0)], {1: 1.0}, (11.0, 0.0))
    ([0, 1], 2)
    """
    V = vertices
    h = np.hypot(V[:, 0] - goal[0], V[:, 1] - goal[1]).tolist()
    ip, nbr, w = adjacency
    n = len(V)
    INF = math.inf
    dist = [INF] * n
    parent = [-1] * n
    closed = bytearray(n)
    heap = []
    for v, c in src:
        if c < dist[v]:
            dist[v] = c
            heapq.heappush(heap, (c + h[v], c, v, -1))
    GOAL = -2
    if direct is not None:
        heap.append((direct, direct, GOAL, -1))
        heapq.heapify(heap)
    expanded = 0
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        f, c, v, p = pop(heap)
        if v == GOAL:
            if p == -1:
                return [], expanded
            path = [p]
            while parent[path[-1]] != -1:
                path.append(parent[path[-1]])
            return path[::-1], expanded
        if closed[v] or c > dist[v]:
            continue
        closed[v] = 1
        parent[v] = p
        expanded += 1
        last = dst.get(v)
        if last is not None:
            push(heap, (c + last, c + last, GOAL, v))
        for k in range(ip[v], ip[v + 1]):
            m = nbr[k]
            if closed[m]:
                continue
            nc = c + w[k]
            if nc < dist[m]:
                dist[m] = nc
                push(heap, (nc + h[m], nc, m, v))
    return None, expanded


def diagnose(roadmap, s, g):
    """A one-line reason why no route joins ``s`` and ``g``: which of them is enclosed, and
    by which keep-out fences.

    Parameters
    ----------
    roadmap : Roadmap
        The roadmap that found no route.
    s, g : ndarray, shape (2,)
        Start and goal, metres.

    Returns
    -------
    str
    """
    x0, y0, x1, y1 = roadmap.bounds
    x0, x1 = min(x0, s[0], g[0]) - 1, max(x1, s[0], g[0]) + 1
    y0, y1 = min(y0, s[1], g[1]) - 1, max(y1, s[1], g[1]) + 1
    blocked = shapely.union_all(shapely.buffer(roadmap.keep_out, roadmap.ce, quad_segs=16))
    free = shapely.difference(shapely.box(x0, y0, x1, y1), blocked)
    parts = shapely.get_parts(free)
    ps, pg = shapely.points(s), shapely.points(g)
    cs = next((p for p in parts if p.intersects(ps)), None)
    cg = next((p for p in parts if p.intersects(pg)), None)
    if cs is not None and cg is not None and cs.equals(cg):
        return (
            "no route found on the roadmap although start and goal share free space "
            f"(gaps barely wider than twice the clearance of {roadmap.clearance:g} m); "
            "try a smaller clearance"
        )
    # the enclosed end is the one whose free pocket is bounded (smaller)
    if cs is None or cg is None:
        label, pocket = ("start", cs) if cg is None else ("goal", cg)
    elif cs.area <= cg.area:
        label, pocket = "start", cs
    else:
        label, pocket = "goal", cg
    if pocket is None:
        return f"the {label} is enclosed by keep-out fences"
    ring = shapely.LinearRing(pocket.exterior.coords)
    near = roadmap.tree.query(ring, predicate="dwithin", distance=roadmap.ce * 1.05 + 0.5)
    names = sorted({roadmap.names[int(k)] for k in np.atleast_1d(near)})
    shown = ", ".join(names[:6]) + (f" (+{len(names) - 6} more)" if len(names) > 6 else "")
    return (
        f"the {label} is enclosed by keep-out fence{'s' if len(names) != 1 else ''} {shown}: "
        f"no gap of twice the clearance ({2 * roadmap.clearance:g} m) leads out"
    )
