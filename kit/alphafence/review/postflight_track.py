"""The post-flight check's walk along a track: each position through the monitor's fence index
and engine, then the straight lines between positions for closest approaches and for
incursions no position shows (:mod:`alphafence.review.postflight` has the report)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np
import shapely

from alphafence.awareness.fenceset import KEEP_IN, KEEP_OUT, WARNING
from alphafence.awareness.sample import Sample
from alphafence.monitor.engine import GLITCH_SLACK_M

KIND_NAMES = {KEEP_OUT: "keep_out", WARNING: "warning", KEEP_IN: "keep_in"}
ALERT_RANK = {"CLEAR": 0, "WARNING": 1, "IMMINENT": 2, "BREACH": 3}
MAX_ALERTS = 1000
TRACK_POINTS = 20_000  # positions kept for a figure (every n-th of a longer flight)
NOTHING = frozenset()


@dataclass
class Incursion:
    """A fence entered (a keep-in fence: left): when, where, how deep."""

    fence: int
    kind: str
    t_in: float  # the first position inside (or the crossing, between positions)
    t_out: float | None  # the first position outside again; None: the log ends inside
    lat: float
    lon: float
    alt_m: float  # height above home where it began
    samples: int = 1
    depth_m: float = 0.0  # deepest: metres inside the fence (keep-in: outside it)
    between_samples: bool = False


@dataclass
class Approach:
    """The track's closest approach to one fence (horizontal metres)."""

    fence: int
    distance_m: float
    t: float
    lat: float
    lon: float
    alt_m: float
    fence_lat: float  # the fence's nearest point
    fence_lon: float
    in_force: bool
    vertical_m: float  # how far above or below the fence's altitude band (0: within it)


def _fill(values, fallback):
    """``values`` with NaNs replaced by ``fallback`` (an array or a number)."""
    bad = ~np.isfinite(values)
    if bad.any():
        values = values.copy()
        values[bad] = fallback[bad] if np.ndim(fallback) else fallback
    return values


class Walker:
    """Walks a track chunk by chunk, filling a :class:`FlightReport`. The fences' AMSL limits
    follow the log's home (its altitude AMSL less its height above home:
    ``FenceSet.set_home``), as the engine's do.

    Parameters
    ----------
    report : FlightReport
    engine : Engine
        Built on ``report.fences``.
    """

    def __init__(self, report, engine):
        self.rep, self.engine = report, engine
        fs = report.fences
        self.fs = fs
        self.cols = {k: j for j, k in enumerate(fs.timed)}
        self.keep_in = [int(k) for k in np.flatnonzero(fs.kind == KEEP_IN)]
        self.open = {}  # fence -> Incursion under way
        self.prev = None  # the last position: (x, y, t, alt, inside, left, active)
        self.next_time = -math.inf
        self.home = None  # home AMSL, when the log gives no height above home
        self.seen = {}  # timed fence -> set of in-force states seen
        self.track, self.kept, self.stride, self.count = [], 0, 1, 0
        self.room = None  # (x, y, clearance, fences' version) of a position outside all

    # -- positions --------------------------------------------------------------------
    def chunk(self, c):
        """Check one :class:`~alphafence.flights.flight_log.TrackChunk`."""
        fs, rep = self.fs, self.rep
        n = len(c)
        if not n:
            return
        if math.isnan(rep.start_t):
            rep.start_t = float(c.t[0])
        rep.end_t = float(c.t[-1])
        if self.home is None and not np.isfinite(c.alt_rel).all():
            self.home = float(c.alt_amsl[0])
        alt = _fill(c.alt_rel, c.alt_amsl - (self.home or 0.0))
        x, y = (np.asarray(v, dtype=float) for v in fs.frame.to_local(c.lon, c.lat))
        vn, ve = self._velocity(c, x, y)
        utc = rep.info.clock == "utc" and bool(self.cols)
        inside, left = [None] * n, [None] * n
        active = np.ones((n, len(self.cols)), dtype=bool)
        breach = np.zeros(n)
        timed = np.array(fs.timed, dtype=int)
        for i in range(n):
            t = float(c.t[i])
            if utc and t >= self.next_time:
                fs.set_time(datetime.fromtimestamp(t, timezone.utc))
                self.next_time = math.floor(t) + 1.0
            fs.set_home(float(c.alt_amsl[i] - alt[i]))
            inside[i], left[i] = self._check(float(x[i]), float(y[i]), float(alt[i]))
            breach[i] = bool(left[i] or any(fs.kind[k] == KEEP_OUT for k in inside[i]))
            active[i] = fs.active[timed]
            self._positions(t, c.lat[i], c.lon[i], alt[i], x[i], y[i], inside[i] | left[i])
            lat, lon, amsl = float(c.lat[i]), float(c.lon[i]), float(c.alt_amsl[i])
            s = Sample(t, lat, lon, float(alt[i]), float(vn[i]), float(ve[i]), alt_amsl_m=amsl)
            self._alerts(self.engine.step(s))
        for k, j in self.cols.items():
            self.seen.setdefault(k, set()).update(np.unique(active[:, j]).tolist())
        self._keep_track(c, alt, breach)
        t = np.asarray(c.t, dtype=float)
        if self.prev is not None:  # the line from the previous chunk's last position
            p = self.prev
            x, y, t, alt = (np.r_[p[key], v] for key, v in zip("xyta", (x, y, t, alt)))
            inside, left = [p["inside"], *inside], [p["left"], *left]
            active = np.vstack([p["active"], active])
        self._segments(x, y, t, alt, inside, left, active)
        self.prev = dict(x=x[-1], y=y[-1], t=t[-1], a=alt[-1], inside=inside[-1], left=left[-1])
        self.prev["active"] = active[-1:]

    def _check(self, x, y, alt):
        """The fences a position is in and the keep-in fences it has left. Within the
        clearance of a position outside every fence (any kind, any altitude) nothing can have
        changed while nothing went in or out of force: no query (see ``clearance``)."""
        fs, room = self.fs, self.room
        if (
            room is not None
            and room[3] == fs.version
            and math.hypot(x - room[0], y - room[1]) < room[2]
        ):
            return NOTHING, NOTHING
        check = fs.check(x, y, alt)
        inside = frozenset(check.inside_keep_out + check.inside_warning)
        left = frozenset(check.outside_keep_in)
        clear = 0.0 if inside or left else fs.clearance(x, y)
        self.room = (x, y, clear, fs.version) if clear > 0 else None
        return inside, left

    def _velocity(self, c, x, y):
        if np.isfinite(c.vn).all() and np.isfinite(c.ve).all():
            return c.vn.astype(float), c.ve.astype(float)
        p = self.prev
        px, py, pt = (x[0], y[0], c.t[0]) if p is None else (p["x"], p["y"], p["t"])
        dt = np.diff(np.concatenate([np.atleast_1d(pt), c.t]))
        dt = np.where(dt > 0, dt, np.inf)
        ve = np.diff(np.concatenate([np.atleast_1d(px), x])) / dt
        vn = np.diff(np.concatenate([np.atleast_1d(py), y])) / dt
        return _fill(c.vn, vn), _fill(c.ve, ve)

    def _positions(self, t, lat, lon, alt, x, y, now):
        fs, rep = self.fs, self.rep
        for k in list(self.open):
            if k not in now:
                self.open.pop(k).t_out = t
        for k in now:
            inc = self.open.get(k)
            if inc is None:
                kind = KIND_NAMES[int(fs.kind[k])]
                inc = Incursion(k, kind, t, None, float(lat), float(lon), float(alt))
                self.open[k] = inc
                rep.incursions.append(inc)
            else:
                inc.samples += 1
            p = shapely.Point(x, y)
            edge = fs.local[k] if fs.kind[k] == KEEP_IN else fs.boundary[k]
            inc.depth_m = max(inc.depth_m, float(shapely.distance(p, edge)))

    def _alerts(self, events):
        for e in events:
            rising = e["event"] == "level" and (
                ALERT_RANK.get(e.get("level"), 0) > ALERT_RANK.get(e.get("previous"), 0)
            )
            if (rising or e["event"] == "gps_glitch") and len(self.rep.alerts) < MAX_ALERTS:
                self.rep.alerts.append(e)

    def _keep_track(self, c, alt, breach):
        idx = np.arange(self.count, self.count + len(c))
        sel = np.flatnonzero(idx % self.stride == 0)
        self.count += len(c)
        self.track.append(np.column_stack([c.t, c.lon, c.lat, alt, breach])[sel])
        self.last = np.array([[c.t[-1], c.lon[-1], c.lat[-1], alt[-1], breach[-1]]])
        self.kept += len(sel)
        if self.kept > 2 * TRACK_POINTS:
            whole = np.concatenate(self.track)[::2]
            self.track, self.kept, self.stride = [whole], len(whole), self.stride * 2

    # -- the lines between positions ---------------------------------------------------
    def _segments(self, x, y, t, alt, inside, left, active):
        fs, rep = self.fs, self.rep
        if len(x) < 2:
            return
        pts = np.column_stack([x, y])
        segs = shapely.linestrings(np.stack([pts[:-1], pts[1:]], axis=1))
        dt = np.diff(t)
        length = np.hypot(np.diff(x), np.diff(y))
        ok = np.flatnonzero(length <= self.engine.options.max_speed_mps * dt + GLITCH_SLACK_M)
        if not ok.size:
            return
        si, fi = fs.tree.query(segs[ok], predicate="dwithin", distance=rep.near_m)
        si = ok[si]
        force = np.ones(len(si), dtype=bool)
        for k, j in self.cols.items():
            m = fi == k
            force[m] = active[si[m], j]
        d = shapely.distance(segs[si], fs.local[fi])
        order = np.lexsort((d, ~force, fi))
        first = order[np.r_[True, fi[order][1:] != fi[order][:-1]]] if order.size else order
        for p in first:
            self._approach(int(si[p]), int(fi[p]), float(d[p]), bool(force[p]), segs, t, alt)
        for p in np.flatnonzero((d == 0.0) & force & (fs.kind[fi] == KEEP_OUT)):
            s, k = int(si[p]), int(fi[p])
            if k not in inside[s] and k not in inside[s + 1]:
                self._between(s, k, shapely.intersection(segs[s], fs.local[k]), segs, t, alt)
        if fs.keep_in_union and len(self.keep_in) > 1:
            self._between_keep_ins(ok, left, active, segs, t, alt)
            return
        for k in self.keep_in:
            j = self.cols.get(k)
            cand = [s for s in ok if k not in left[s] and k not in left[s + 1]]
            cand = [s for s in cand if j is None or active[s, j]]
            if not cand:
                continue
            out = np.flatnonzero(~shapely.covers(fs.local[k], segs[cand]))
            for s in np.asarray(cand)[out]:
                part = shapely.difference(segs[s], fs.local[k])
                self._between(int(s), k, part, segs, t, alt)

    def _between_keep_ins(self, ok, left, active, segs, t, alt):
        """Under the union of keep-in fences: a line between two positions inside it that
        leaves every keep-in in force there (named after the first of them)."""
        fs = self.fs
        for s in ok:
            if left[s] or left[s + 1]:
                continue
            live = [k for k in self.keep_in
                    if (j := self.cols.get(k)) is None or active[s, j]]  # fmt: skip
            if not live:
                continue
            allowed = shapely.union_all(fs.local[live])
            if shapely.covers(allowed, segs[s]):
                continue
            self._between(int(s), live[0], shapely.difference(segs[s], allowed), segs, t, alt)

    def _at(self, seg, point, t, alt, s):
        """Time and height above home at ``point`` on segment ``s`` (linear)."""
        f = float(shapely.line_locate_point(seg, point, normalized=True))
        f = f if math.isfinite(f) else 0.0
        return t[s] + f * (t[s + 1] - t[s]), alt[s] + f * (alt[s + 1] - alt[s])

    def _approach(self, s, k, d, force, segs, t, alt):
        best = self.rep.closest.get(k)
        if best is not None and (best.in_force, -best.distance_m) >= (force, -d):
            return
        fs = self.fs
        line = shapely.shortest_line(segs[s], fs.local[k])
        (ax, ay), (bx, by) = shapely.get_coordinates(line)
        when, height = self._at(segs[s], shapely.Point(ax, ay), t, alt, s)
        lon, lat = fs.frame.to_wgs84(np.array([ax, bx]), np.array([ay, by]))
        vertical = max(fs.alt_min[k] - height, height - fs.alt_max[k], 0.0)
        self.rep.closest[k] = Approach(
            k, d, float(when), float(lat[0]), float(lon[0]), float(height),
            float(lat[1]), float(lon[1]), force, float(vertical),
        )  # fmt: skip

    def _between(self, s, k, part, segs, t, alt):
        """A fence crossed (or a keep-in fence left) between positions ``s`` and ``s + 1``."""
        fs = self.fs
        if part.is_empty or k in self.open:
            return
        parts = shapely.get_parts(part)  # the middle of the longest piece
        piece = parts[int(np.argmax(shapely.length(parts)))]
        if piece.geom_type == "LineString":
            point = shapely.line_interpolate_point(piece, 0.5, normalized=True)
        else:  # the line touches the fence at a point
            point = shapely.get_point(piece, 0) if piece.geom_type != "Point" else piece
        when, height = self._at(segs[s], point, t, alt, s)
        if fs.kind[k] == KEEP_OUT and not fs.alt_min[k] <= height <= fs.alt_max[k]:
            return
        lon, lat = fs.frame.to_wgs84(point.x, point.y)
        if fs.kind[k] == KEEP_IN:  # the farthest point outside (at a vertex, near enough)
            depth = shapely.distance(shapely.points(shapely.get_coordinates(part)), fs.local[k])
        else:
            depth = shapely.distance(point, fs.boundary[k])
        kind = KIND_NAMES[int(fs.kind[k])]
        when = float(when)
        self.rep.incursions.append(
            Incursion(
                k,
                kind,
                when,
                when,
                float(lat),
                float(lon),
                float(height),
                0,
                float(np.max(depth)),
                True,
            )  # fmt: skip
        )

    def finish(self):
        """Close the report: incursions in time order, what was in force, the kept track."""
        rep = self.rep
        rep.incursions.sort(key=lambda i: i.t_in)
        for k, states in self.seen.items():
            rep.in_force[k] = "partly" if len(states) > 1 else ("yes" if True in states else "no")
        if self.track:
            rep.track = np.concatenate([*self.track, self.last])
