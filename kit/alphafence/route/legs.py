"""Mission legs checked against fences: which legs cross or graze a keep-out fence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.planner import fence_label as default_fence_label


@dataclass
class LegIssue:
    """A leg that crosses or comes closer than the clearance to a keep-out fence.

    Attributes
    ----------
    leg : int
        The leg's number, from 1.
    start, end : str
        The labels of its waypoints.
    fence : str
        The fence, as ``fence_label`` names it.
    distance_m : float
        Least distance from the leg to the fence (0 when it crosses).
    crosses : bool
    """

    leg: int  # 1-based
    start: str
    end: str
    fence: str
    distance_m: float  # 0 when the leg crosses the fence
    crosses: bool


def check_legs(waypoints, records, clearance=20.0, fence_label=None):
    """Legs between consecutive waypoints that cross (distance 0) or graze (closer than
    ``clearance``) a keep-out fence, computed exactly in one local metric frame.

    Parameters
    ----------
    waypoints : list of Waypoint
        The positions the mission flies through, in order (``read_mission``).
    records : list of FenceRecord
    clearance : float
        Legs closer than this (metres) to a keep-out fence are issues.
    fence_label : callable, optional
        Names a fence in the issues (default: site id and name).

    Returns
    -------
    issues : list of LegIssue
        By leg, then fence.
    legs : list of tuple
        ``(number, from, to)`` for every leg, numbered from 1.
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
    """
    label = fence_label or default_fence_label
    keep_out = [r for r in records if r.kind == "keep_out"]
    warning = [r for r in records if r.kind == "warning"]
    pts = np.array([(w.lon, w.lat) for w in waypoints], float)
    legs = list(zip(range(1, len(pts)), waypoints[:-1], waypoints[1:]))
    if not keep_out and not warning:
        return [], legs, set()
    coords = np.concatenate([pts] + [shapely.get_coordinates(r.geometry) for r in keep_out])
    frame = LocalFrame.around_coords(coords)
    x, y = frame.to_local(pts[:, 0], pts[:, 1])
    xy = np.column_stack([x, y])
    segs = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
    issues = []
    if keep_out:
        ko = frame.geom_to_local(np.array([r.geometry for r in keep_out], dtype=object))
        tree = shapely.STRtree(ko)
        i, j = tree.query(segs, predicate="dwithin", distance=clearance)
        d = shapely.distance(segs[i], ko[j])
        for a, b, dist in sorted(zip(i.tolist(), j.tolist(), d.tolist())):
            issues.append(
                LegIssue(
                    a + 1,
                    waypoints[a].label,
                    waypoints[a + 1].label,
                    label(keep_out[b]),
                    float(dist),
                    dist <= 0.0,
                )
            )
    warning_legs = set()
    if warning:
        wa = frame.geom_to_local(np.array([r.geometry for r in warning], dtype=object))
        i, _ = shapely.STRtree(wa).query(segs, predicate="intersects")
        warning_legs = {int(k) + 1 for k in i}
    return issues, legs, warning_legs
