"""Split a large build into tile jobs that give exactly the untiled build's sites.

Features of one class whose extents, grown by the join distance (and points' and lines'
widths), meet directly or through others form a *region* (:func:`sites.region_labels`); a site
never spans two regions. Each region belongs to the tile (a square of ``tile_deg`` degrees)
that holds the centre of its extent, and goes to that tile's job whole: the features of a
region that reach across the tile's edge travel with it, a halo exactly as wide as the join
reaches. So no site is split or duplicated at a tile edge, whatever the tile size. Tiles are
taken row by row and packed into jobs of about ``target`` features (a crowded tile makes
several jobs; a region is never cut).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from alphafence.fencing.regions import floats, region_labels

TILE_DEG = 0.25  # about 28 km north-south
TARGET_FEATURES = 2_000  # per job


@dataclass
class TileJob:
    """One unit of work: whole regions, each a sorted array of feature indices.

    Attributes
    ----------
    number : int
        Its place in the build's order (outputs are written in this order).
    tiles : list of tuple
        ``(row, column)`` of the tiles it covers.
    indices : ndarray of int
        Its features, region after region.
    ends : ndarray of int
        Where each region ends in ``indices``.
    """

    number: int
    tiles: list
    indices: np.ndarray
    ends: np.ndarray

    @property
    def size(self) -> int:
        """The number of features."""
        return len(self.indices)

    @property
    def regions(self) -> list:
        """Feature indices per region, ascending (the database's order)."""
        return np.split(self.indices, self.ends[:-1])

    @property
    def spans(self) -> list:
        """``(start, end)`` of each region in :attr:`indices`."""
        ends = self.ends.tolist()
        return list(zip([0, *ends[:-1]], ends))


@dataclass
class JobPlan:
    """The tile jobs of a build, held as a few arrays (a number or two per feature and per
    region) and made into :class:`TileJob` one at a time.

    Attributes
    ----------
    indices : ndarray of int
        Every feature, job after job, region after region.
    ends : ndarray of int
        Where each region ends in ``indices``.
    rows, cols : ndarray of int
        Each region's tile.
    firsts : ndarray of int
        Each job's first region, and the number of regions last.
    """

    indices: np.ndarray
    ends: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    firsts: np.ndarray

    def __len__(self):
        return len(self.firsts) - 1

    def __getitem__(self, number) -> TileJob:
        if not -len(self) <= number < len(self):
            raise IndexError(number)
        number %= len(self)
        r0, r1 = int(self.firsts[number]), int(self.firsts[number + 1])
        start = int(self.ends[r0 - 1]) if r0 else 0
        tiles = []
        for tile in zip(self.rows[r0:r1].tolist(), self.cols[r0:r1].tolist()):
            if not tiles or tiles[-1] != tile:
                tiles.append(tile)
        return TileJob(number, tiles, self.indices[start : self.ends[r1 - 1]],
                       self.ends[r0:r1] - start)  # fmt: skip

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def plan_regions(bounds, widths, classes, join_m):
    """Region label per feature: regions of different classes never share a label.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
    widths : ndarray, shape (n,)
    classes : ndarray of int, shape (n,)
    join_m : float

    Returns
    -------
    ndarray of int
        Numbered in the order of each region's first feature.
    """
    return region_labels(bounds, widths, join_m, classes=np.asarray(classes))


def plan_jobs(bounds, widths, classes, join_m, tile_deg=TILE_DEG, target=TARGET_FEATURES):
    """Tile jobs covering every feature once.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
        ``minlon, minlat, maxlon, maxlat`` per feature.
    widths : ndarray, shape (n,)
        Metres points and lines are widened by.
    classes : ndarray of int, shape (n,)
        Features of different classes never share a site.
    join_m : float
    tile_deg : float
        Tile edge in degrees.
    target : int
        Features per job to aim for.

    Returns
    -------
    JobPlan
        A sequence of :class:`TileJob`.

    Examples
    --------
    >>> import numpy as np
    >>> b = np.array([[14.0, 35.0, 14.001, 35.001], [14.3, 35.0, 14.301, 35.001],
    ...               [14.30105, 35.0, 14.302, 35.001]])
    >>> jobs = plan_jobs(b, np.zeros(3), np.zeros(3, int), 25.0, tile_deg=0.25, target=1)
    >>> [(j.tiles, [r.tolist() for r in j.regions]) for j in jobs]
    [([(500, 776)], [[0]]), ([(500, 777)], [[1, 2]])]
    """
    bounds = floats(bounds).reshape(-1, 4)
    n = len(bounds)
    empty = np.empty(0, np.int64)
    if n == 0:
        return JobPlan(empty, empty, empty, empty, np.zeros(1, np.int64))
    labels = plan_regions(bounds, widths, classes, join_m)
    index = labels.dtype  # one number per feature, as small as region_labels made it
    order = np.argsort(labels, kind="stable").astype(index)  # region after region, in db order
    labels = labels[order]
    new = np.empty(n, bool)
    new[0] = True
    np.not_equal(labels[1:], labels[:-1], out=new[1:])
    del labels
    starts = np.flatnonzero(new).astype(index)
    del new
    # each region's tile, from the centre of its extent (a column at a time: one number per
    # feature in memory at once)
    tile = []
    for axis, offset in ((1, 90.0), (0, 180.0)):
        column = bounds[order, axis]
        centre = np.minimum.reduceat(column, starts).astype(float)
        column = bounds[order, axis + 2]
        centre += np.maximum.reduceat(column, starts)
        del column
        centre = (centre / 2.0 + offset) / tile_deg
        tile.append(np.floor(centre, out=centre).astype(np.int32))
        del centre
    row, col = tile
    del tile
    sizes = np.diff(starts, append=index.type(n))
    tile_order = np.lexsort((starts, col, row)).astype(index)  # row by row, then the db's order
    row, col = row[tile_order], col[tile_order]
    sizes = sizes[tile_order]
    ends = np.cumsum(sizes, dtype=index)
    firsts = _pack(ends, target)
    # each region's features, in tile order: its start in ``order`` plus 0, 1, ...
    shift = np.repeat(starts[tile_order] - (ends - sizes), sizes)
    del starts, tile_order, sizes
    shift += np.arange(n, dtype=index)
    indices = order[shift]
    return JobPlan(indices, ends, row, col, firsts)


def _pack(ends, target):
    """Each job's first region, and the number of regions last: regions taken in order, a job
    closing once it holds ``target`` features (greedy), from the regions' cumulative ends.

    Examples
    --------
    >>> _pack(np.cumsum([3, 1, 1, 5, 2]), 4).tolist()
    [0, 2, 4, 5]
    """
    target = max(1, int(target))
    firsts, r = [0], 0
    while r < len(ends):
        base = int(ends[r - 1]) if r else 0
        # the first region whose end reaches base + target closes the job
        r = min(int(np.searchsorted(ends, base + target, side="left")), len(ends) - 1) + 1
        firsts.append(r)
    return np.asarray(firsts, dtype=np.int64)
