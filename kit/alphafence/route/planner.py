"""Route between two WGS84 positions around the keep-out fences of a fence file.

The fences are projected once into one local metric frame (``LocalFrame``); the
:class:`~alphafence.route.roadmap.Roadmap` lives in that frame and is reused for every query.
"""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.route.roadmap import Roadmap, Route


def fence_label(record) -> str:
    """How messages name a fence: its site id, and its name when it has one.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.formats.fence_geojson import FenceRecord
    >>> box = shapely.box(14.500, 35.900, 14.502, 35.902)
    >>> fence_label(FenceRecord("power/way/7", "keep_out", box, name="Substation"))
    'power/way/7 (Substation)'
    """
    if record.name and record.name != record.site_id:
        return f"{record.site_id} ({record.name})"
    return str(record.site_id)


class FenceRoadmap:
    """A :class:`Roadmap` over the keep-out fences of ``records`` (``FenceRecord``), warning
    layers costing more than open air.

    Parameters
    ----------
    records : list of FenceRecord
        Keep-out fences are avoided, warning layers cost more; keep-in fences are ignored.
    clearance : float
        Least distance from any keep-out fence, metres.
    extra_lonlat : sequence of tuple
        ``(lon, lat)`` positions the frame and the roadmap should also cover (a mission's
        start and goal).
    frame : LocalFrame, optional
        By default one centred on the keep-out fences and ``extra_lonlat``.
    **roadmap_options
        Passed to :class:`Roadmap` (``spacing``, ``warning_cost``...).

    Raises
    ------
    ValueError
        No keep-out fence and no position to place a frame.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.formats.fence_geojson import FenceRecord
    >>> box = shapely.box(14.500, 35.900, 14.502, 35.902)
    >>> start, goal = (14.497, 35.901), (14.505, 35.901)  # west and east of the fence
    >>> roadmap = FenceRoadmap([FenceRecord("power/way/7", "keep_out", box)], 20.0, [start, goal])
    >>> route, lonlat = roadmap.route(start, goal)
    >>> round(route.length_m), route.min_clearance_m >= 20, lonlat[-1].tolist()
    (783, True, [14.505, 35.901])
    """

    def __init__(self, records, clearance=20.0, extra_lonlat=(), frame=None, **roadmap_options):
        self.records = list(records)
        self.keep_out_records = [r for r in self.records if r.kind == "keep_out"]
        self.warning_records = [r for r in self.records if r.kind == "warning"]
        coords = [shapely.get_coordinates(r.geometry) for r in self.keep_out_records]
        extra = np.asarray(list(extra_lonlat), float).reshape(-1, 2)
        coords.append(extra)
        allc = np.concatenate(coords) if coords else extra
        if frame is None:
            if not len(allc):
                raise ValueError("no keep-out fences and no positions to place a frame")
            frame = LocalFrame.around_coords(allc)
        self.frame = frame
        ko = frame.geom_to_local(
            np.array([r.geometry for r in self.keep_out_records], dtype=object)
        )
        wa = frame.geom_to_local(np.array([r.geometry for r in self.warning_records], dtype=object))
        bounds = None
        if len(extra):
            x, y = frame.to_local(extra[:, 0], extra[:, 1])
            bounds = (np.min(x), np.min(y), np.max(x), np.max(y))
        self.roadmap = Roadmap(
            list(ko),
            list(wa),
            clearance=clearance,
            names=[fence_label(r) for r in self.keep_out_records],
            bounds=bounds,
            **roadmap_options,
        )

    def to_local(self, lonlat):
        """A ``(lon, lat)`` position in the roadmap's metres, as an array ``[x, y]``."""
        x, y = self.frame.to_local(lonlat[0], lonlat[1])
        return np.array([float(x), float(y)])

    def route(self, start_lonlat, goal_lonlat, smooth=True) -> tuple[Route, np.ndarray]:
        """(the route in metres, its vertices as an (n, 2) array of lon, lat)."""
        r = self.roadmap.route(self.to_local(start_lonlat), self.to_local(goal_lonlat), smooth)
        lon, lat = self.frame.to_wgs84(r.xy[:, 0], r.xy[:, 1])
        lonlat = np.column_stack([lon, lat])
        lonlat[0] = start_lonlat  # the exact positions asked for, not a round trip
        lonlat[-1] = goal_lonlat
        return r, lonlat
