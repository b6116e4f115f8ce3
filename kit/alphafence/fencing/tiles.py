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

from alphafence.fencing.regions import region_labels

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
    regions : list of ndarray
        Feature indices per region, ascending (the database's order).
    """

    number: int
    tiles: list
    regions: list

    @property
    def size(self) -> int:
        """The number of features."""
        return int(sum(len(r) for r in self.regions))


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
    """
    labels = np.empty(len(classes), dtype=np.int64)
    next_label = 0
    for c in np.unique(classes):
        idx = np.flatnonzero(classes == c)
        lab = region_labels(bounds[idx], widths[idx], join_m)
        labels[idx] = lab + next_label
        next_label += int(lab.max()) + 1
    return labels


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
    list of TileJob

    Examples
    --------
    >>> import numpy as np
    >>> b = np.array([[14.0, 35.0, 14.001, 35.001], [14.3, 35.0, 14.301, 35.001],
    ...               [14.30105, 35.0, 14.302, 35.001]])
    >>> jobs = plan_jobs(b, np.zeros(3), np.zeros(3, int), 25.0, tile_deg=0.25, target=1)
    >>> [(j.tiles, [r.tolist() for r in j.regions]) for j in jobs]
    [([(500, 776)], [[0]]), ([(500, 777)], [[1, 2]])]
    """
    n = len(classes)
    if n == 0:
        return []
    labels = plan_regions(np.asarray(bounds), np.asarray(widths), np.asarray(classes), join_m)
    order = np.lexsort((np.arange(n), labels))
    sorted_labels = labels[order]
    starts = np.flatnonzero(np.r_[True, sorted_labels[1:] != sorted_labels[:-1]])
    b = np.asarray(bounds)[order]
    lo = np.minimum.reduceat(b[:, :2], starts, axis=0)
    hi = np.maximum.reduceat(b[:, 2:], starts, axis=0)
    centre = (lo + hi) / 2.0
    col = np.floor((centre[:, 0] + 180.0) / tile_deg).astype(np.int64)
    row = np.floor((centre[:, 1] + 90.0) / tile_deg).astype(np.int64)
    ends = np.r_[starts[1:], n]
    tile_order = np.lexsort((starts, col, row))  # row by row, then the database's order
    jobs, current, tiles = [], [], []
    size = 0
    for r in tile_order:
        tile = (int(row[r]), int(col[r]))
        if size >= target:
            jobs.append(TileJob(len(jobs), tiles, current))
            current, tiles, size = [], [], 0
        current.append(order[starts[r] : ends[r]])
        if not tiles or tiles[-1] != tile:
            tiles.append(tile)
        size += int(ends[r] - starts[r])
    if current:
        jobs.append(TileJob(len(jobs), tiles, current))
    return jobs
