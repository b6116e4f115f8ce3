"""All fences in one metric frame with an STRtree: the monitor's per-position queries.

One check costs a few STRtree queries in C, independent of how many fences there are.
The frame is centred on the fences; positions farther than ``recentre_m`` from its origin
get a new frame (the index is rebuilt), so distances stay accurate to centimetres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame

KEEP_OUT, WARNING, KEEP_IN = 0, 1, 2
KIND_CODES = {"keep_out": KEEP_OUT, "warning": WARNING, "keep_in": KEEP_IN}


@dataclass
class Hit:
    """The nearest keep-out fence to a position."""

    index: int  # fence index
    distance_m: float  # to the fence (0 when inside)
    inside: bool


@dataclass
class Check:
    """What one position means against every fence."""

    inside_keep_out: list  # fence indices the position is inside (within their altitudes)
    inside_warning: list
    outside_keep_in: list  # keep-in fences the position has left
    nearest_keep_out: Hit | None  # nearest keep-out boundary ahead of or around the vehicle
    breach_ahead: tuple | None  # (fence index, metres along the track) within the look-ahead


class FenceSet:
    """Every fence in one metric frame, indexed for the monitor's per-position checks.

    Parameters
    ----------
    records : iterable of FenceRecord
        The fences (keep-out, warning, keep-in), with their altitude limits and ED-269
        applicability (``properties["zone"]["applicability"]``).
    frame : LocalFrame, optional
        The metric frame; centred on the fences if omitted.

    Raises
    ------
    ValueError
        When there are no fences.
    """

    def __init__(self, records, frame: LocalFrame | None = None):
        self.records = list(records)
        if not self.records:
            raise ValueError("no fences")
        geoms = np.array([r.geometry for r in self.records], dtype=object)
        self.frame = frame or LocalFrame.around(geoms)
        self.kind = np.array([KIND_CODES[r.kind] for r in self.records])
        self.alt_min = np.array(
            [-math.inf if r.alt_min_m is None else r.alt_min_m for r in self.records]
        )
        self.alt_max = np.array(
            [math.inf if r.alt_max_m is None else r.alt_max_m for r in self.records]
        )
        self.applicability = [
            ((r.properties or {}).get("zone") or {}).get("applicability") for r in self.records
        ]
        from alphafence.monitor.applicability import timed

        self.timed = [k for k, a in enumerate(self.applicability) if timed(a)]
        self.active = np.ones(len(self.records), dtype=bool)
        self.version = 0  # changes whenever what is in force, or the frame, changes
        self._build(geoms)

    @classmethod
    def from_geojson(cls, path):
        """The fences of a fence GeoJSON file (``alphafence build``'s output); InputError
        when it holds none (a monitor with nothing to watch is a mistake, said at once)."""
        from alphafence.errors import InputError
        from alphafence.formats.fence_read import read_fence_file as read_fences

        records = read_fences(path)
        if not records:
            raise InputError(path, "holds no fences: nothing to monitor")
        return cls(records)

    def _build(self, geoms):
        self.local = self.frame.geom_to_local(geoms)
        shapely.prepare(self.local)
        self.boundary = shapely.boundary(self.local)
        self.tree = shapely.STRtree(self.local)
        self._by_kind = {}
        timed = np.zeros(len(self.records), dtype=bool)
        timed[self.timed] = True
        for code in (KEEP_OUT, WARNING, KEEP_IN):
            # the nearest-fence tree holds the fences always in force; time-windowed ones
            # (few) are measured directly while they are active
            idx = np.flatnonzero((self.kind == code) & ~timed)
            self._by_kind[code] = (idx, shapely.STRtree(self.local[idx]) if idx.size else None)
        self._timed_keep_out = [k for k in self.timed if self.kind[k] == KEEP_OUT]
        self._keep_in = [int(k) for k in np.flatnonzero(self.kind == KEEP_IN)]

    def recentre(self, lon, lat):
        """A new frame centred on ``(lon, lat)``, and the index rebuilt in it."""
        self.frame = LocalFrame(lon, lat)
        self._build(np.array([r.geometry for r in self.records], dtype=object))
        self.version += 1

    def _in_alt(self, idx, alt):
        return (self.alt_min[idx] <= alt) & (alt <= self.alt_max[idx]) & self.active[idx]

    def set_time(self, when):
        """Switch time-windowed (ED-269 applicability) fences on or off for ``when`` (an aware
        datetime). Inactive fences are neither inside nor nearest. Call it every few seconds."""
        from alphafence.monitor.applicability import is_active

        for k in self.timed:
            now = is_active(self.applicability[k], when)
            if now != self.active[k]:
                self.active[k] = now
                self.version += 1

    def clearance(self, x, y) -> float:
        """The distance from ``(x, y)`` to the nearest fence of any kind, in force or not
        (0 inside one): the room in which nothing about the fences can change."""
        _, d = self.tree.query_nearest(shapely.Point(x, y), return_distance=True)
        return float(d[0]) if d.size else math.inf

    def check(self, x, y, alt=0.0, vx=0.0, vy=0.0, lookahead_m=0.0) -> Check:
        """Position (metres in ``self.frame``), altitude and horizontal velocity.

        The common case (nowhere near a fence) costs three STRtree look-ups in C."""
        p = shapely.Point(x, y)
        inside = self.tree.query(p, predicate="intersects")
        inside_out, inside_warn, inside_in = [], [], set()
        if inside.size:
            inside = inside[self._in_alt(inside, alt)]
            kinds = self.kind[inside]
            inside_out = inside[kinds == KEEP_OUT].tolist()
            inside_warn = inside[kinds == WARNING].tolist()
            inside_in = set(inside[kinds == KEEP_IN].tolist())
        outside_in = [k for k in self._keep_in if self.active[k] and k not in inside_in]
        nearest = None
        ahead = None
        ko_idx, ko_tree = self._by_kind[KEEP_OUT]
        if ko_tree is not None:
            j, d = ko_tree.query_nearest(p, return_distance=True, all_matches=False)
            if j.size:
                k = int(ko_idx[j[0]])
                nearest = Hit(k, float(d[0]), float(d[0]) == 0.0)
        for k in self._timed_keep_out:
            if self.active[k]:
                d = float(shapely.distance(p, self.local[k]))
                if nearest is None or d < nearest.distance_m:
                    nearest = Hit(k, d, d == 0.0)
        speed = math.hypot(vx, vy)
        # a fence can only lie ahead within the look-ahead if the nearest one does
        if nearest is not None and 0 < nearest.distance_m <= lookahead_m and speed > 0.05:
            ahead = self._ahead(p, x, y, vx / speed, vy / speed, lookahead_m, inside_out)
        return Check(inside_out, inside_warn, outside_in, nearest, ahead)

    def near(self, x, y, alt, tol_m) -> int | None:
        """A fence in force at ``alt`` that forbids the point ``(x, y)`` or whose boundary is
        within ``tol_m`` of it (a keep-out it is in or near, a keep-in it has left or is near
        the edge of), or None. Warning layers forbid nothing.

        Examples
        --------
        >>> from alphafence.formats.fence_geojson import FenceRecord
        >>> frame = LocalFrame(14.5, 35.9)
        >>> square = FenceRecord("x", "keep_out", frame.geom_to_wgs84(shapely.box(0, 0, 10, 10)))
        >>> fences = FenceSet([square], frame=frame)
        >>> fences.near(11.0, 5.0, 20.0, 2.0), fences.near(15.0, 5.0, 20.0, 2.0)
        (0, None)
        """
        p = shapely.Point(x, y)
        near = self.tree.query(p, predicate="dwithin", distance=tol_m)
        near = near[self._in_alt(near, alt)] if near.size else near
        for k in near:
            if self.kind[k] == KEEP_OUT:
                return int(k)
            if self.kind[k] == KEEP_IN and shapely.distance(p, self.boundary[k]) <= tol_m:
                return int(k)
        for k in self._keep_in:
            if self._in_alt(k, alt) and not self.local[k].contains(p):
                return k
        return None

    def _ahead(self, p, x, y, ux, uy, lookahead_m, skip):
        ko_idx, ko_tree = self._by_kind[KEEP_OUT]
        ray = shapely.LineString([(x, y), (x + ux * lookahead_m, y + uy * lookahead_m)])
        cand = ko_idx[ko_tree.query(ray, predicate="intersects")] if ko_tree else ko_idx[:0]
        timed = [
            k for k in self._timed_keep_out if self.active[k] and ray.intersects(self.local[k])
        ]
        if timed:
            cand = np.concatenate([cand, np.asarray(timed, dtype=cand.dtype)])
        if skip:
            cand = cand[~np.isin(cand, skip)]
        if not cand.size:
            return None
        # one vectorised intersection and distance over every candidate
        along = shapely.distance(p, shapely.intersection(ray, self.local[cand]))
        along = np.where(np.isnan(along), np.inf, along)  # an empty intersection: not ahead
        j = int(np.argmin(along))
        return (int(cand[j]), float(along[j])) if np.isfinite(along[j]) else None
