"""A uniform grid over the fences for the monitor's per-position check: the fences a position
may be inside and the keep-outs that may be nearest to it, looked up by cell, not searched.

Each cell lists (sorted by fence index) the fences whose envelope overlaps it, and the
keep-outs that can be the nearest one to some point of it: with ``d`` the distance from the
cell's centre to the nearest keep-out and ``h`` the cell's half diagonal, every point of the
cell has a keep-out within ``d + h``, so any keep-out nearest to it is within ``d + 2h`` of the
centre (the triangle inequality). A check then costs one vectorised GEOS call over a few
fences for each question, with the same answers as asking every fence; positions outside the
grid are left to the STRtree.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

MIN_CELLS = 16_384  # fine enough that a cell of a small set holds a few fences
MAX_CELLS = 1 << 20
CELLS_PER_FENCE = 1
SLACK = 1e-9  # relative slack on the candidates' radius, for rounding


def _csr(rows, values, count):
    """Values grouped by row, sorted by row then value: ``(indptr, values)``."""
    order = np.lexsort((values, rows))
    indptr = np.zeros(count + 1, dtype=np.intp)
    np.cumsum(np.bincount(rows, minlength=count), out=indptr[1:])
    return indptr, values[order].astype(np.intp)


class FenceGrid:
    """The fences of a metric frame by grid cell.

    Parameters
    ----------
    local : numpy.ndarray of shapely geometries
        Every fence, in metres.
    keep_out : numpy.ndarray of int
        The indices (into ``local``) of the keep-outs the nearest-fence question counts.
    keep_out_tree : shapely.STRtree or None
        An STRtree of ``local[keep_out]`` (None when ``keep_out`` is empty).
    """

    def __init__(self, local, keep_out, keep_out_tree):
        n = len(local)
        x0, y0, x1, y1 = shapely.total_bounds(local) if n else (0.0, 0.0, 0.0, 0.0)
        width, height = max(x1 - x0, 1.0), max(y1 - y0, 1.0)
        cells = min(max(CELLS_PER_FENCE * n, MIN_CELLS), MAX_CELLS)
        self.size = size = math.sqrt(width * height / cells)
        self.x0, self.y0 = float(x0), float(y0)
        self.nx, self.ny = int(width // size) + 1, int(height // size) + 1
        count = self.nx * self.ny
        # the cells each fence's envelope overlaps (the same arithmetic as cell())
        b = shapely.bounds(local)
        ok = np.isfinite(b).all(axis=1)
        b, fence = b[ok], np.flatnonzero(ok)
        ix0, ix1 = self._col(b[:, 0]), self._col(b[:, 2])
        iy0, iy1 = self._row(b[:, 1]), self._row(b[:, 3])
        cols, per = ix1 - ix0 + 1, (ix1 - ix0 + 1) * (iy1 - iy0 + 1)
        f = np.repeat(np.arange(len(fence)), per)
        k = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
        row_cells = (iy0[f] + k // cols[f]) * self.nx + ix0[f] + k % cols[f]
        self.cover = _csr(row_cells, fence[f], count)
        self.near = None
        if keep_out_tree is not None:
            ii, jj = np.meshgrid(np.arange(self.nx), np.arange(self.ny))
            centres = shapely.points(
                self.x0 + (ii.ravel() + 0.5) * size, self.y0 + (jj.ravel() + 0.5) * size
            )
            _, d = keep_out_tree.query_nearest(centres, return_distance=True, all_matches=False)
            self.reach = d + size * math.sqrt(2.0)  # the candidates' radius around the centre
            reach = self.reach * (1.0 + SLACK) + SLACK * size
            c, j = keep_out_tree.query(centres, predicate="dwithin", distance=reach)
            self.near = _csr(c, np.asarray(keep_out)[j], count)

    def _col(self, x):
        return np.clip(np.floor((x - self.x0) / self.size), 0, self.nx - 1).astype(np.intp)

    def _row(self, y):
        return np.clip(np.floor((y - self.y0) / self.size), 0, self.ny - 1).astype(np.intp)

    def cell(self, x, y) -> int:
        """The cell holding ``(x, y)``, or -1 outside the grid (no fence there)."""
        i = math.floor((x - self.x0) / self.size)
        j = math.floor((y - self.y0) / self.size)
        if 0 <= i < self.nx and 0 <= j < self.ny:
            return j * self.nx + i
        return -1

    def inside(self, local, cell, x, y):
        """The fences (indices, ascending) that ``(x, y)`` in ``cell`` intersects."""
        indptr, fences = self.cover
        cand = fences[indptr[cell] : indptr[cell + 1]]
        if not cand.size:
            return cand
        return cand[shapely.intersects_xy(local[cand], x, y)]

    def nearest(self, local, cell, p):
        """The nearest keep-out to the point ``p`` in ``cell`` and its distance, the lowest
        index among equals, and the cell's keep-outs with their distances from ``p``:
        ``(index, metres, (candidates, distances))``."""
        indptr, fences = self.near
        cand = fences[indptr[cell] : indptr[cell + 1]]
        d = shapely.distance(p, local[cand])
        j = int(np.argmin(d))
        return int(cand[j]), float(d[j]), (cand, d)

    def holds(self, cell, metres) -> bool:
        """Whether the keep-outs of ``cell`` include every one within ``metres`` of any of
        its points (those farther than its candidates' radius less a half diagonal are not
        there)."""
        return metres + self.size * math.sqrt(0.5) <= self.reach[cell]
