"""Mission legs checked against fences: which legs cross or graze a keep-out fence, and which
leave (or come near the edge of) a keep-in fence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.planner import fence_label as default_fence_label


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
    legs), in the order first flown: ``[(from, to), ...]``."""
    seen, out = set(), []
    for a, b in zip(waypoints[:-1], waypoints[1:]):
        key = (a.label, a.lon, a.lat, b.label, b.lon, b.lat)
        if key not in seen:
            seen.add(key)
            out.append((a, b))
    return out


def check_legs(waypoints, records, clearance=20.0, fence_label=None):
    """Legs between consecutive waypoints that cross (distance 0) or graze (closer than
    ``clearance``) a keep-out fence, or leave (distance 0) or come closer than ``clearance``
    to the edge of a keep-in fence (the vehicle must stay inside each, as ArduPilot and the
    monitor have it), computed exactly in one local metric frame.

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
    >>> from alphafence.formats.fence_geojson import FenceRecord
    >>> from alphafence.formats.mission import Waypoint
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
    keep_out = [r for r in records if r.kind == "keep_out"]
    keep_in = [r for r in records if r.kind == "keep_in"]
    warning = [r for r in records if r.kind == "warning"]
    pairs = distinct_legs(waypoints)
    legs = [(n, a, b) for n, (a, b) in enumerate(pairs, start=1)]
    if not legs or not (keep_out or keep_in or warning):
        return [], legs, set()
    ends = np.array([[(a.lon, a.lat), (b.lon, b.lat)] for a, b in pairs], float)
    coords = np.concatenate(
        [ends.reshape(-1, 2)] + [shapely.get_coordinates(r.geometry) for r in keep_out + keep_in]
    )
    frame = LocalFrame.around_coords(coords)
    x, y = frame.to_local(ends[..., 0].ravel(), ends[..., 1].ravel())
    segs = shapely.linestrings(np.column_stack([x, y]).reshape(-1, 2, 2))
    issues = []

    def issue(a, fence, dist, crosses, inside=False):
        start, end = pairs[a]
        issues.append(LegIssue(a + 1, start.label, end.label, fence, dist, crosses, inside))

    if keep_out:
        ko = frame.geom_to_local(np.array([r.geometry for r in keep_out], dtype=object))
        tree = shapely.STRtree(ko)
        i, j = tree.query(segs, predicate="dwithin", distance=clearance)
        d = shapely.distance(segs[i], ko[j])
        for a, b, dist in sorted(zip(i.tolist(), j.tolist(), d.tolist())):
            issue(a, label(keep_out[b]), float(dist), dist <= 0.0)
    for r in keep_in:
        area = frame.geom_to_local(r.geometry)
        shapely.prepare(area)
        inside = shapely.covers(area, segs)
        edge = shapely.distance(segs, area.boundary)
        for a in range(len(segs)):
            if not inside[a]:
                issue(a, label(r), 0.0, True, True)
            elif edge[a] < clearance:
                issue(a, label(r), float(edge[a]), False, True)
    issues.sort(key=lambda t: (t.leg, t.keep_in))
    warning_legs = set()
    if warning:
        wa = frame.geom_to_local(np.array([r.geometry for r in warning], dtype=object))
        i, _ = shapely.STRtree(wa).query(segs, predicate="intersects")
        warning_legs = {int(k) + 1 for k in i}
    return issues, legs, warning_legs
