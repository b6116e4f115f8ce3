"""All fences in one metric frame with an STRtree: the monitor's per-position queries.

One check looks its fences up in a grid (:mod:`alphafence.awareness.fencegrid`): a GEOS call
over the few fences of the position's cell for each question, with the answers of a plain
loop over every fence (among equals, the lowest index); the STRtree answers outside the grid.
The frame is centred on the fences; positions farther than ``recentre_m`` from its origin
get a new frame (the index is rebuilt), so distances stay accurate to centimetres.

Altitudes are heights above home. A fence's limits keep their vertical references (ED-269 and
ED-318 zones in ``properties["zone"]``, KML and OpenAir on the fence: :func:`reference`); an
AMSL limit is moved to home's altitude AMSL (:meth:`FenceSet.set_home`, from the vehicle's
altitude AMSL less its height above home) and, until home is known, holds at every altitude.
AGL limits and limits without a reference are compared with the height above home (no terrain
data: AGL is taken as above home). The monitor's engine and the post-flight check both do this.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.awareness.applicability import active_within, timed
from alphafence.awareness.fencegrid import FenceGrid
from alphafence.awareness.rays import FenceEdges
from alphafence.awareness.references import AMSL_REFERENCES, GROUND_REFERENCES, reference
from alphafence.geo.frame import LocalFrame

KEEP_OUT, WARNING, KEEP_IN = 0, 1, 2
KIND_CODES = {"keep_out": KEEP_OUT, "warning": WARNING, "keep_in": KEEP_IN}
NEAREST_DIRECT = 64  # up to this many keep-outs in reach are measured without the tree
HOME_TOLERANCE_M = 0.01  # a home AMSL this close to the last one moves no limit


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
    nearest_keep_out: Hit | None  # nearest keep-out in force within the vertical reach
    breach_ahead: tuple | None  # (fence index, metres along the track) within the look-ahead
    keep_out_any_m: float = math.inf  # to the nearest keep-out in force at any altitude


class FenceSet:
    """Every fence in one metric frame, indexed for the monitor's per-position checks.

    Parameters
    ----------
    records : iterable of FenceRecord
        The fences (keep-out, warning, keep-in), with their altitude limits and ED-269
        applicability (``properties["zone"]["applicability"]``).
    frame : LocalFrame, optional
        The metric frame; centred on the fences if omitted.
    keep_in_union : bool
        Inside any keep-in in force is inside (the kit's fences: areas one may fly in), or
        only inside every one (False: ArduPilot's default, :mod:`~alphafence.mavlink.inclusions`).

    Raises
    ------
    ValueError
        When there are no fences and no ``frame`` (a set of no fence needs one).
    """

    def __init__(self, records, frame: LocalFrame | None = None, keep_in_union: bool = True):
        self.records, self.keep_in_union = list(records), keep_in_union
        if not self.records and frame is None:
            raise ValueError("no fences, and no frame to place them in")
        geoms = np.array([r.geometry for r in self.records], dtype=object)
        self.frame = frame or LocalFrame.around(geoms)
        self.kind = np.array([KIND_CODES[r.kind] for r in self.records])
        # the limits as given, each in its own reference; alt_min and alt_max above home
        lower = [-math.inf if r.alt_min_m is None else r.alt_min_m for r in self.records]
        upper = [math.inf if r.alt_max_m is None else r.alt_max_m for r in self.records]
        self.limits = (np.array(lower, dtype=float), np.array(upper, dtype=float))
        self.references = [(reference(r, "lower"), reference(r, "upper")) for r in self.records]
        self.amsl = [  # per limit (lower, upper): the fences whose limit there is AMSL
            np.flatnonzero([(ref[j] in AMSL_REFERENCES) for ref in self.references])
            for j in range(2)
        ]
        self.amsl = [idx[np.isfinite(self.limits[j][idx])] for j, idx in enumerate(self.amsl)]
        self.home_amsl: float | None = None
        self.alt_min, self.alt_max = self.limits[0].copy(), self.limits[1].copy()
        self.alt_min[self.amsl[0]], self.alt_max[self.amsl[1]] = -math.inf, math.inf
        self.applicability = [
            ((r.properties or {}).get("zone") or {}).get("applicability") for r in self.records
        ]
        self.timed = [k for k, a in enumerate(self.applicability) if timed(a)]
        self.active = np.ones(len(self.records), dtype=bool)
        self.version = 0  # changes whenever what is in force, or the frame, changes
        self._build(geoms)

    @classmethod
    def from_geojson(cls, path, empty_ok: bool = False):
        """The fences of a fence GeoJSON file (``alphafence build``'s output); InputError
        when it holds none (nothing to watch is a mistake, said at once) unless ``empty_ok``
        (a live source's empty offline copy: a set of no fence)."""
        from alphafence.errors import InputError
        from alphafence.fencefiles.fence_read import read_fence_file as read_fences

        records = read_fences(path)
        if not records and not empty_ok:
            raise InputError(path, "holds no fences: nothing to monitor")
        return cls(records, frame=None if records else LocalFrame(0.0, 0.0))

    def _build(self, geoms):
        self.local = self.frame.read_geom(geoms)  # edges straight in lon/lat, as ArduPilot reads
        shapely.prepare(self.local)
        self.boundary = shapely.boundary(self.local)
        self.tree = shapely.STRtree(self.local)
        self._bounds = shapely.total_bounds(self.local) if len(self.local) else np.zeros(4)
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
        self._keep_out_all = np.flatnonzero(self.kind == KEEP_OUT)
        self._grid = None  # built at the first check
        self._edges = None  # the fences' segments, for the track ahead

    def index(self) -> None:
        """Build the position check's grid now (a monitor does it before the flight: at
        100,000 fences it takes seconds), not at the first check."""
        if self._grid is None:
            self._grid = FenceGrid(self.local, *self._by_kind[KEEP_OUT])
            self._edges = FenceEdges(self.local)

    def recentre(self, lon, lat):
        """A new frame centred on ``(lon, lat)``, and the index rebuilt in it."""
        self.frame = LocalFrame(lon, lat)
        self._build(np.array([r.geometry for r in self.records], dtype=object))
        self.version += 1

    def set_home(self, home_amsl) -> bool:
        """Place the AMSL limits for a home at ``home_amsl`` metres AMSL (the vehicle's
        altitude AMSL less its height above home): ``alt_min`` and ``alt_max`` stay heights
        above home. Returns whether a limit moved (not for a home within a centimetre of the
        last one, nor for one that is not finite). Clearances are horizontal, at any altitude:
        no ``version`` change is needed."""
        if home_amsl is None or not math.isfinite(home_amsl):
            return False
        if self.home_amsl is not None and abs(home_amsl - self.home_amsl) < HOME_TOLERANCE_M:
            return False
        self.home_amsl = float(home_amsl)
        for j, arr in enumerate((self.alt_min, self.alt_max)):
            idx = self.amsl[j]
            arr[idx] = self.limits[j][idx] - self.home_amsl
        return bool(self.amsl[0].size or self.amsl[1].size)

    def bands(self, frame):
        """Each fence's lower and upper limits as altitudes in ``frame`` measure them: for
        positions whose altitude is known in that reference only (a mission's legs).

        ``"home"``: above home (:attr:`alt_min`, :attr:`alt_max`; AMSL limits placed by
        :meth:`set_home`); ``"amsl"``: AMSL limits as given, the others placed by the home;
        ``"terrain"``: above the ground below, AGL limits as given; None: not known. A limit
        that cannot be compared in ``frame`` (an AMSL one before the home is known, any but
        an AGL one above the terrain) is NaN; no limit is -inf or inf.

        Returns
        -------
        tuple of numpy.ndarray
            ``(lower, upper)``, one value per fence.

        Examples
        --------
        >>> from alphafence.fencefiles.fence_geojson import FenceRecord
        >>> box, amsl = shapely.box(14.5, 35.9, 14.501, 35.901), {"lower_reference": "AMSL"}
        >>> fs = FenceSet([FenceRecord("a", "keep_out", box, alt_min_m=120.0),
        ...                FenceRecord("b", "keep_out", box, alt_min_m=300.0, properties=amsl)])
        >>> fs.bands("home")[0].tolist(), fs.bands("amsl")[0].tolist(), fs.bands("home")[1]
        ([120.0, nan], [nan, 300.0], array([inf, inf]))
        >>> _ = fs.set_home(100.0)
        >>> fs.bands("home")[0].tolist(), fs.bands("amsl")[0].tolist()
        ([120.0, 200.0], [220.0, 300.0])
        """
        home, out = self.home_amsl, []
        for j in (0, 1):
            given = self.limits[j]
            amsl = np.zeros(len(given), dtype=bool)
            amsl[self.amsl[j]] = True
            if frame == "home":
                lim = (self.alt_min, self.alt_max)[j].copy()
                lim[amsl] = np.nan if home is None else lim[amsl]
            elif frame == "amsl":
                lim = np.where(amsl, given, np.nan if home is None else given + home)
            elif frame == "terrain":
                ground = np.array([ref[j] in GROUND_REFERENCES for ref in self.references])
                lim = np.where(ground, given, np.nan)
            else:
                lim = np.full(len(given), np.nan)
            none = ~np.isfinite(given)
            lim[none] = given[none]
            out.append(lim)
        return out[0], out[1]

    @property
    def amsl_sites(self) -> list:
        """The site ids of the fences with a (finite) AMSL limit, each once, in order."""
        idx = np.union1d(self.amsl[0], self.amsl[1])
        return list(dict.fromkeys(self.records[k].site_id for k in idx))

    def altitude_notes(self) -> list:
        """What comparing the fences' limits in their references approximates, one sentence
        each (flight levels, ellipsoid heights, AGL without terrain data)."""
        said = {
            self.references[k][j]
            for j in (0, 1)
            for k in np.flatnonzero(np.isfinite(self.limits[j]))
        }  # the references of the limits there are
        notes = [AMSL_REFERENCES[r] for r in sorted(said & AMSL_REFERENCES.keys())]
        notes = [text for text in notes if text]  # plain AMSL needs no note
        if said - AMSL_REFERENCES.keys():
            notes.append("AGL limits compared with the height above home (no terrain data)")
        return notes

    def _in_alt(self, idx, alt):
        return (self.alt_min[idx] <= alt) & (alt <= self.alt_max[idx]) & self.active[idx]

    def _in_reach(self, idx, alt, vertical_m):
        """Fences in force whose band is within ``vertical_m`` of ``alt``."""
        lo, hi = self.alt_min[idx] - vertical_m, self.alt_max[idx] + vertical_m
        return (lo <= alt) & (alt <= hi) & self.active[idx]

    def set_time(self, when, slack_s: float = 0.0):
        """Switch time-windowed (ED-269 applicability) fences on or off for ``when`` (aware; in
        force anywhere within ``slack_s`` of it). Inactive ones are neither inside nor nearest."""
        if not self.timed:
            return
        for k in self.timed:
            now = active_within(self.applicability[k], when, slack_s)
            if now != self.active[k]:
                self.active[k] = now
                self.version += 1

    def clearance(self, x, y) -> float:
        """The distance from ``(x, y)`` to the nearest fence of any kind, in force or not
        (0 inside one): the room in which nothing about the fences can change."""
        _, d = self.tree.query_nearest(shapely.Point(x, y), return_distance=True)
        return float(d[0]) if d.size else math.inf

    def check(self, x, y, alt=0.0, vx=0.0, vy=0.0, lookahead_m=0.0, vertical_m=math.inf):
        """What a position (metres in ``self.frame``, ``alt`` above home) moving at
        ``(vx, vy)`` m/s means against every fence: a :class:`Check`.

        The position is inside a fence when within its band; the prediction (the nearest
        keep-out, a breach ahead within ``lookahead_m``) counts the keep-out fences whose band
        is within ``vertical_m`` of ``alt`` (infinite, the default: every keep-out, as a wall
        from the ground up). The grid is built at the first check."""
        p = shapely.points((x, y))  # a third of shapely.Point(x, y)'s cost
        self.index()
        cell = self._grid.cell(x, y)  # -1 outside the grid: the STRtree answers
        if cell >= 0:
            inside = self._grid.inside(self.local, cell, x, y)
        else:
            inside = np.sort(self.tree.query(p, predicate="intersects"))
        holding = inside  # at any altitude
        inside_out, inside_warn, inside_in = [], [], set()
        if inside.size:
            inside = inside[self._in_alt(inside, alt)]
            kinds = self.kind[inside]
            inside_out = inside[kinds == KEEP_OUT].tolist()
            inside_warn = inside[kinds == WARNING].tolist()
            inside_in = set(inside[kinds == KEEP_IN].tolist())
        outside_in = self._left(inside_in)
        nearest = near = None
        ahead = None
        ko_idx, ko_tree = self._by_kind[KEEP_OUT]
        if ko_tree is not None and cell >= 0:
            k, d, near = self._grid.nearest(self.local, cell, p)
            nearest = Hit(k, d, d == 0.0)
        elif ko_tree is not None:
            j, d = ko_tree.query_nearest(p, return_distance=True, all_matches=True)
            if j.size:  # the lowest index among equals
                k = int(ko_idx[j].min())
                nearest = Hit(k, float(d[0]), float(d[0]) == 0.0)
        for k in self._timed_keep_out:
            if self.active[k]:
                d = float(shapely.distance(p, self.local[k]))
                if nearest is None or (d, k) < (nearest.distance_m, nearest.index):
                    nearest = Hit(k, d, d == 0.0)
        any_m = math.inf if nearest is None else nearest.distance_m
        banded = not math.isinf(vertical_m)
        if banded and nearest is not None and not self._in_reach(nearest.index, alt, vertical_m):
            nearest = self._nearest_in_reach(p, alt, vertical_m, any_m)
        speed = math.hypot(vx, vy)
        # a fence can only lie ahead within the look-ahead if the nearest one does
        if nearest is not None and 0 < nearest.distance_m <= lookahead_m and speed > 0.05:
            reach = (alt, vertical_m) if banded else None
            if near is not None and not self._grid.holds(cell, lookahead_m):
                near = None  # the cell's candidates may miss a keep-out within the look-ahead
            u = (vx / speed, vy / speed)
            ahead = self._ahead(x, y, *u, lookahead_m, inside_out, reach, near, holding.tolist())
        return Check(inside_out, inside_warn, outside_in, nearest, ahead, any_m)

    def _nearest_in_reach(self, p, alt, vertical_m, start_m):
        """The nearest keep-out in force whose band is within ``vertical_m`` of ``alt``, or
        None: a few such fences are measured directly, more within a growing square around
        ``p`` (from ``start_m``, the nearest at any altitude) until one is within it."""
        ko = self._keep_out_all
        ok = np.zeros(len(self.records), dtype=bool)
        ok[ko] = self._in_reach(ko, alt, vertical_m)
        count = int(np.count_nonzero(ok))
        if not count:
            return None
        x0, y0, x1, y1 = self._bounds
        far = math.hypot(max(abs(p.x - x0), abs(p.x - x1)), max(abs(p.y - y0), abs(p.y - y1)))
        r = max(2.0 * start_m, 100.0) if count > NEAREST_DIRECT else math.inf
        while True:
            if math.isinf(r):
                cand = np.flatnonzero(ok)
            else:  # every fence within r of p has its envelope in this square
                cand = np.sort(self.tree.query(shapely.box(p.x - r, p.y - r, p.x + r, p.y + r)))
                cand = cand[ok[cand]]
            if cand.size:
                d = shapely.distance(p, self.local[cand])
                j = int(np.argmin(d))
                if d[j] <= r:
                    return Hit(int(cand[j]), float(d[j]), float(d[j]) == 0.0)
            r = 4.0 * r if 4.0 * r < far else math.inf

    def near(self, x, y, alt, tol_m) -> int | None:
        """A fence in force at ``alt`` that forbids the point ``(x, y)`` or whose boundary is
        within ``tol_m`` of it (a keep-out it is in or near, a keep-in it has left or is near
        the edge of), or None. Warning layers forbid nothing.

        Examples
        --------
        >>> from alphafence.fencefiles.fence_geojson import FenceRecord
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
        left = self._left({k for k in self._keep_in if self.local[k].contains(p)} & set(near))
        return left[0] if left else None

    def _left(self, inside_in) -> list:
        """The keep-ins in force a position in ``inside_in`` has left, by ``keep_in_union``."""
        live = [k for k in self._keep_in if self.active[k]]
        return ([] if inside_in & set(live) else live) if self.keep_in_union else [
            k for k in live if k not in inside_in]  # fmt: skip

    def _ahead(self, x, y, ux, uy, lookahead_m, skip, reach=None, near=None, holding=()):
        """The first keep-out in force along the ray (those in ``skip`` left out; with
        ``reach = (alt, vertical_m)`` only those whose band is within reach); ``near``, the
        grid cell's keep-outs when they hold all within the look-ahead; ``holding``, the
        fences the start lies in (at any altitude)."""
        ko_idx, ko_tree = self._by_kind[KEEP_OUT]
        lower = None
        if near is not None:
            cand, lower = near
        elif ko_tree is not None:
            end = (x + ux * lookahead_m, y + uy * lookahead_m)
            box = shapely.box(min(x, end[0]), min(y, end[1]), max(x, end[0]), max(y, end[1]))
            cand = ko_idx[ko_tree.query(box)]
        else:
            cand = ko_idx[:0]
        timed = [k for k in self._timed_keep_out if self.active[k]]
        if timed:
            cand = np.concatenate([cand, np.asarray(timed, dtype=cand.dtype)])
            lower = None
        if skip or reach is not None:
            keep = np.ones(cand.size, dtype=bool)
            if skip:
                keep &= ~np.isin(cand, skip)
            if reach is not None and cand.size:
                keep &= self._in_reach(cand, *reach)
            cand = cand[keep]
            lower = None if lower is None else lower[keep]
        if self._edges is None:
            self._edges = FenceEdges(self.local)
        return self._edges.first_hit(x, y, ux, uy, lookahead_m, cand, holding, lower)
