"""Mission legs checked against fences: which legs cross or graze a keep-out fence, and which
leave (or come near the edge of) a keep-in fence, each leg at its altitudes against each
fence's altitude band where the bands are given.

A leg's altitude changes along it as its profile says
(:class:`~alphafence.flights.mission_flight.Waypoint`). A leg crosses a keep-out fence when the
part of it within the fence's band enters it; it grazes the fence when it comes closer than the
clearance to the fence's volume, measured as the larger of the horizontal and the vertical
distance (a box around the fence: never more than the straight-line distance). A leg leaves a
keep-in fence when any of it is outside the fence, or above or below its band; it is near the
edge when closer than the clearance to a side, the floor or the ceiling. A leg whose altitude
is not known, or a limit that cannot be compared with it (NaN in the bands), counts as within a
keep-out fence's band throughout and as outside a keep-in fence's band.

Legs and fences are taken as ArduPilot takes them: a fence's edges, and the line a leg is
flown along, are straight lines in lon/lat (followed in the metric frame to within a
centimetre, :func:`~alphafence.route.planner.read_legs`), not the straight chords between
their projected ends: a 50 km leg at 64° N bows about 100 m toward the equator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.planner import READ_M, lonlat_legs
from alphafence.route.planner import fence_label as default_fence_label

KINDS = ("keep_out", "keep_in", "warning")


@dataclass
class LegIssue:
    """A leg that crosses or comes closer than the clearance to a keep-out fence, or leaves or
    comes closer than the clearance to the edge of a keep-in fence.

    Attributes
    ----------
    leg : int
        The leg's number, from 1.
    start, end : str
        The labels of its waypoints.
    fence : str
        The fence, as ``fence_label`` names it.
    distance_m : float
        Least distance from the leg to the keep-out fence, or to the keep-in fence's edge
        (0 when it crosses, or leaves).
    crosses : bool
        It enters the keep-out fence, or leaves the keep-in fence.
    keep_in : bool
        The fence is a keep-in fence.
    """

    leg: int  # 1-based
    start: str
    end: str
    fence: str
    distance_m: float  # 0 when the leg crosses the fence
    crosses: bool
    keep_in: bool = False


def distinct_legs(waypoints):
    """The legs between consecutive waypoints, each once (a loop flown again flies the same
    legs at the same altitudes), in the order first flown: ``[(from, to), ...]``."""
    seen, out = set(), []
    for a, b in zip(waypoints[:-1], waypoints[1:]):
        key = (a.label, a.lon, a.lat, b.label, b.lon, b.lat, b.frame, _profile(b))
        if key not in seen:
            seen.add(key)
            out.append((a, b))
    return out


def _profile(w):
    """The leg's altitude profile to waypoint ``w``, or () when not known."""
    prof = tuple(getattr(w, "profile", ()) or ())
    return prof if len(prof) >= 2 else ()


def _within(profile, lo, hi):
    """The stretches ``(t0, t1)`` (fractions of the leg) where the profile is within
    ``[lo, hi]``."""
    out = []
    for (ta, za), (tb, zb) in zip(profile[:-1], profile[1:]):
        if za == zb:
            if lo <= za <= hi:
                out.append((ta, tb))
            continue
        s0, s1 = sorted(((lo - za) / (zb - za), (hi - za) / (zb - za)))
        s0, s1 = max(s0, 0.0), min(s1, 1.0)
        if s0 <= s1:
            out.append((ta + s0 * (tb - ta), ta + s1 * (tb - ta)))
    return out


def _part_distance(frame, ends, profile, lo, hi, fence):
    """Horizontal distance from the part of the leg within ``[lo, hi]`` to ``fence`` (inf when
    no part is); ``ends`` the leg's (lon, lat), the part as flown along its lon/lat line."""
    spans = _within(profile, lo, hi)
    if not spans:
        return math.inf
    a, b = ends
    t = np.asarray(spans, float)[..., None]
    parts = frame.read_geom(shapely.linestrings(a + t * (b - a)), READ_M)
    return float(shapely.distance(parts, fence).min())


def _box_distance(frame, ends, profile, lo, hi, fence, clearance, whole):
    """The leg's distance to a fence's volume (0: it enters it), the larger of the horizontal
    and the vertical distance, or None when not within ``clearance``; ``whole`` is the whole
    leg's horizontal distance, the answer when its altitude is within the band throughout or
    not known."""
    lo = -math.inf if math.isnan(lo) else lo
    hi = math.inf if math.isnan(hi) else hi
    zs = [z for _, z in profile]
    if not profile or lo <= min(zs) and max(zs) <= hi:
        return whole
    if _part_distance(frame, ends, profile, lo, hi, fence) == 0.0:
        return 0.0
    if _part_distance(frame, ends, profile, lo - clearance, hi + clearance, fence) > clearance:
        return None
    low, high = 0.0, clearance  # the least m whose part within m of the band is within m
    for _ in range(32):
        m = 0.5 * (low + high)
        if _part_distance(frame, ends, profile, lo - m, hi + m, fence) <= m:
            high = m
        else:
            low = m
    return high


def _keep_in_margin(profile, lo, hi):
    """How far the leg stays within a keep-in fence's band (negative: it leaves it; -inf when
    a limit cannot be compared, or the leg's altitude is not known and the band has one)."""
    if math.isnan(lo) or math.isnan(hi):
        return -math.inf
    if not profile:
        return math.inf if (lo, hi) == (-math.inf, math.inf) else -math.inf
    zs = [z for _, z in profile]
    return min(min(zs) - lo, hi - max(zs))


def check_legs(waypoints, records, clearance=20.0, fence_label=None, bands=None):
    """Legs between consecutive waypoints that cross (distance 0) or graze (closer than
    ``clearance``) a keep-out fence, or leave (distance 0) or come closer than ``clearance``
    to the edge of a keep-in fence (the vehicle must stay inside each, as ArduPilot and the
    monitor have it), computed exactly in one local metric frame; each leg as flown (a
    straight line in lon/lat) at its altitudes against each fence's band when ``bands`` are
    given (see the module).

    Parameters
    ----------
    waypoints : list of Waypoint
        The positions the mission flies through, in order (``read_mission``); a leg flown
        more than once is checked, and numbered, once.
    records : list of FenceRecord
    clearance : float
        Legs closer than this (metres) to a keep-out fence, or to a keep-in fence's edge, are
        issues.
    fence_label : callable, optional
        Names a fence in the issues (default: site id and name).
    bands : callable, optional
        ``bands(frame)`` -> ``(lower, upper)``, arrays over ``records``: each fence's limits
        as altitudes in a leg's reference (its last waypoint's ``frame``) measure them, NaN
        where a limit cannot be compared, -inf and inf where there is none
        (:meth:`~alphafence.awareness.fenceset.FenceSet.bands`). Omitted: every fence holds at
        every altitude.

    Returns
    -------
    issues : list of LegIssue
        By leg, then fence (keep-out fences first).
    legs : list of tuple
        ``(number, from, to)`` for every distinct leg, numbered from 1.
    warning_legs : set of int
        Numbers of the legs that enter a warning layer.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> from alphafence.flights.mission import Waypoint
    >>> fence = FenceRecord("power/way/7", "keep_out", shapely.box(14.500, 35.900, 14.502, 35.902))
    >>> mission = [Waypoint("home", 14.497, 35.901), Waypoint("item 1", 14.505, 35.901)]
    >>> issues, legs, warning_legs = check_legs(mission, [fence])
    >>> issues[0].leg, issues[0].fence, issues[0].crosses
    (1, 'power/way/7', True)
    >>> area = FenceRecord("area", "keep_in", shapely.box(14.49, 35.89, 14.503, 35.91))
    >>> [(i.fence, i.crosses, i.keep_in) for i in check_legs(mission, [area])[0]]
    [('area', True, True)]
    """
    label = fence_label or default_fence_label
    index = {kind: [k for k, r in enumerate(records) if r.kind == kind] for kind in KINDS}
    keep_out, keep_in, warning = ([records[k] for k in index[kind]] for kind in KINDS)
    pairs = distinct_legs(waypoints)
    legs = [(n, a, b) for n, (a, b) in enumerate(pairs, start=1)]
    if not legs or not (keep_out or keep_in or warning):
        return [], legs, set()
    ends = np.array([[(a.lon, a.lat), (b.lon, b.lat)] for a, b in pairs], float)
    coords = np.concatenate(
        [ends.reshape(-1, 2)] + [shapely.get_coordinates(r.geometry) for r in keep_out + keep_in]
    )
    frame = LocalFrame.around_coords(coords)
    lines = lonlat_legs(ends[:, 0], ends[:, 1])  # each end's longitude the short way
    ends = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    segs = frame.read_geom(lines, READ_M)  # the legs as flown, straight in lon/lat
    profiles = [_profile(b) if b.frame is not None else () for _, b in pairs]
    limits = {}

    def band(a, k):
        """Fence ``k``'s (index in ``records``) limits as leg ``a``'s altitudes measure them."""
        if bands is None:
            return -math.inf, math.inf
        ref = pairs[a][1].frame if profiles[a] else None
        if ref not in limits:
            limits[ref] = bands(ref)
        return float(limits[ref][0][k]), float(limits[ref][1][k])

    def box(a, k, geom, whole, reach):
        return _box_distance(frame, ends[a], profiles[a], *band(a, k), geom, reach, whole)

    issues = []

    def issue(a, fence, dist, crosses, inside=False):
        start, end = pairs[a]
        issues.append(LegIssue(a + 1, start.label, end.label, fence, dist, crosses, inside))

    if keep_out:
        ko = frame.read_geom(np.array([r.geometry for r in keep_out], dtype=object), READ_M)
        tree = shapely.STRtree(ko)
        i, j = tree.query(segs, predicate="dwithin", distance=clearance)
        d = shapely.distance(segs[i], ko[j])
        for a, b, dist in sorted(zip(i.tolist(), j.tolist(), d.tolist())):
            dist = box(a, index["keep_out"][b], ko[b], dist, clearance)
            if dist is not None:
                issue(a, label(keep_out[b]), float(dist), dist <= 0.0)
    for k, r in zip(index["keep_in"], keep_in):
        area = frame.read_geom(r.geometry, READ_M)
        shapely.prepare(area)
        inside = shapely.covers(area, segs)
        edge = shapely.distance(segs, area.boundary)
        for a in range(len(segs)):
            margin = min(float(edge[a]), _keep_in_margin(profiles[a], *band(a, k)))
            if not inside[a] or margin < 0:
                issue(a, label(r), 0.0, True, True)
            elif margin < clearance:
                issue(a, label(r), margin, False, True)
    issues.sort(key=lambda t: (t.leg, t.keep_in))
    warning_legs = set()
    if warning:
        wa = frame.read_geom(np.array([r.geometry for r in warning], dtype=object), READ_M)
        i, j = shapely.STRtree(wa).query(segs, predicate="intersects")
        warning_legs = {
            int(a) + 1
            for a, b in zip(i.tolist(), j.tolist())
            if box(a, index["warning"][b], wa[b], 0.0, 0.0) == 0.0
        }
    return issues, legs, warning_legs
