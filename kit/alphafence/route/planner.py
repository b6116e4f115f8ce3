"""Route between two WGS84 positions around the keep-out fences of a fence file, and legs as
ArduPilot flies them.

The fences are read once into one local metric frame (``LocalFrame.read_geom``: their edges
straight lines in lon/lat, as ArduPilot reads them); the
:class:`~alphafence.route.roadmap.Roadmap` lives in that frame and is reused for every query.

ArduPilot flies a leg between two waypoints as the straight line between their lon/lat too,
which in a metric frame bows away from the straight chord the roadmap planned (about
``L**2 * tan(lat) / (8 * R)``: 1 cm for a 700 m leg at 36°, 100 m for a 50 km leg at 64°).
:func:`split_legs` cuts each leg whose lon/lat reading comes too close to a fence into pieces
along its planned line, so that every piece, flown in lon/lat, keeps what the plan kept.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import shapely

from alphafence.geo.frame import LocalFrame
from alphafence.geo.lonlat import READ_TOLERANCE_M
from alphafence.route.roadmap import EPS_CLEAR, Roadmap, Route

READ_M = READ_TOLERANCE_M  # fences and legs are read along their lon/lat lines to 1 cm
# a leg flown in lon/lat keeps this much more than the clearance from a fence as read: the
# fence's and the leg's readings (1 cm each) and the waypoints' 1e-7 degrees (under 8 mm)
FLOWN_SLACK_M = 0.03
SPLIT_M = EPS_CLEAR - FLOWN_SLACK_M  # pieces bowing this little keep FLOWN_SLACK_M: done
MAX_PIECES = 4  # a leg is cut into at most this many pieces a round (only those at fault again)


def fence_label(record) -> str:
    """How messages name a fence: its site id, and its name when it has one.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> box = shapely.box(14.500, 35.900, 14.502, 35.902)
    >>> fence_label(FenceRecord("power/way/7", "keep_out", box, name="Substation"))
    'power/way/7 (Substation)'
    """
    if record.name and record.name != record.site_id:
        return f"{record.site_id} ({record.name})"
    return str(record.site_id)


def lonlat_legs(a, b):
    """Legs from ``a[i]`` to ``b[i]`` (``(lon, lat)`` arrays, shape (n, 2)) as lon/lat
    LineStrings, each end's longitude taken the short way (beyond 180° across the
    antimeridian, as :func:`~alphafence.geo.lonlat.densify_lonlat` reads them).

    Examples
    --------
    >>> [round(v, 6) for v in lonlat_legs([[179.9, 10.0]], [[-179.9, 10.0]])[0].coords[1]]
    [180.1, 10.0]
    """
    a = np.asarray(a, float).reshape(-1, 2)
    b = np.asarray(b, float).reshape(-1, 2).copy()
    b[:, 0] = a[:, 0] + (b[:, 0] - a[:, 0] + 180.0) % 360.0 - 180.0
    return shapely.linestrings(np.stack([a, b], axis=1))


def read_legs(frame, lonlat):
    """The legs between consecutive ``(lon, lat)`` vertices as ArduPilot flies them, in
    ``frame``'s metres: straight lines in lon/lat, followed to within ``READ_M``.

    Parameters
    ----------
    frame : LocalFrame
    lonlat : array_like, shape (n, 2)

    Returns
    -------
    ndarray of LineString, shape (n - 1,)

    Examples
    --------
    >>> frame = LocalFrame(10.5, 64.0)
    >>> leg = read_legs(frame, [(10.0, 64.0), (11.0, 64.0)])[0]  # 49 km along the parallel
    >>> x, y = frame.to_local(np.array([10.0, 11.0]), np.array([64.0, 64.0]))
    >>> round(shapely.hausdorff_distance(leg, shapely.LineString(np.column_stack([x, y]))))
    96
    """
    p = np.asarray(lonlat, float).reshape(-1, 2)
    return frame.read_geom(lonlat_legs(p[:-1], p[1:]), READ_M)


def split_legs(frame, xy, lonlat, at_fault, tolerance_m=SPLIT_M, rounds=32):
    """A route whose legs, flown as straight lon/lat lines, keep what its metric legs keep:
    each leg ``at_fault`` finds fault with is cut, at points along its planned metric line,
    into pieces that bow less (``ceil(sqrt(bow / tolerance_m))`` of them, at most
    ``MAX_PIECES`` a round, since a bow grows with the square of the length), and pieces still
    at fault are cut again, until none is or each bows at most ``tolerance_m``.

    Parameters
    ----------
    frame : LocalFrame
    xy : ndarray, shape (n, 2)
        The route as planned, metres of ``frame``.
    lonlat : ndarray, shape (n, 2)
        The same vertices, lon, lat.
    at_fault : callable
        ``at_fault(readings, chords)`` -> bool per leg: its lon/lat reading (:func:`read_legs`)
        comes too close to a fence, where its planned chord (a metric LineString) does not.
    tolerance_m : float
        A piece whose reading strays at most this far from its chord is not cut again.
    rounds : int
        At most this many rounds of cuts.

    Returns
    -------
    xy, lonlat : ndarray, shape (m, 2)
        The route with waypoints added along its legs (the given ones kept exactly).

    Examples
    --------
    >>> frame = LocalFrame(10.5, 64.0)
    >>> xy = np.array([[-40e3, 0.0], [40e3, 0.0]])  # 80 km east along the frame's geodesic
    >>> lonlat = np.column_stack(frame.to_wgs84(xy[:, 0], xy[:, 1]))
    >>> south = shapely.box(-1e3, -400.0, 1e3, -30.0)  # the lon/lat line bows 256 m south
    >>> def at_fault(readings, chords):
    ...     return shapely.distance(readings, south) < 20.03
    >>> xy2, lonlat2 = split_legs(frame, xy, lonlat, at_fault)
    >>> len(xy2), bool(shapely.distance(read_legs(frame, lonlat2), south).min() >= 20.03)
    (5, True)
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    lonlat = np.asarray(lonlat, float).reshape(-1, 2)
    for _ in range(rounds):
        if len(xy) < 2:
            break
        readings = read_legs(frame, lonlat)
        chords = shapely.linestrings(np.stack([xy[:-1], xy[1:]], axis=1))
        bow = shapely.hausdorff_distance(readings, chords)
        cut = np.asarray(at_fault(readings, chords), bool) & (bow > tolerance_m)
        if not cut.any():
            break
        pieces = np.ones(len(cut), int)
        pieces[cut] = np.clip(np.ceil(np.sqrt(bow[cut] / tolerance_m)), 2, MAX_PIECES)
        new_xy, new_lonlat = [xy[:1]], [lonlat[:1]]
        for i, k in enumerate(pieces.tolist()):
            if k > 1:
                p = xy[i] + np.arange(1, k)[:, None] / k * (xy[i + 1] - xy[i])
                lon, lat = frame.to_wgs84(p[:, 0], p[:, 1])
                new_xy.append(p)
                new_lonlat.append(np.column_stack([lon, lat]))
            new_xy.append(xy[i + 1 : i + 2])
            new_lonlat.append(lonlat[i + 1 : i + 2])
        xy, lonlat = np.concatenate(new_xy), np.concatenate(new_lonlat)
    return xy, lonlat


def flown_distance(tree, readings):
    """The least distance of each reading (:func:`read_legs`) to the geometries of ``tree``
    (an STRtree; inf when it holds none).

    Examples
    --------
    >>> tree = shapely.STRtree([shapely.box(0, 0, 1, 1)])
    >>> flown_distance(tree, [shapely.LineString([(3, 0), (3, 5)])])
    array([2.])
    """
    readings = np.asarray(readings, dtype=object).reshape(-1)
    d = np.full(len(readings), np.inf)
    if len(tree) and len(readings):
        (i, _), dist = tree.query_nearest(readings, return_distance=True, all_matches=False)
        d[i] = dist
    return d


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
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
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
        ko = frame.read_geom(
            np.array([r.geometry for r in self.keep_out_records], dtype=object), READ_M
        )
        wa = frame.read_geom(
            np.array([r.geometry for r in self.warning_records], dtype=object), READ_M
        )
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
        """(the route in metres, its vertices as an (n, 2) array of lon, lat): legs whose
        lon/lat reading would come closer to a keep-out fence than the clearance split
        (:func:`split_legs`), the clearance measured on the legs as flown."""
        r = self.roadmap.route(self.to_local(start_lonlat), self.to_local(goal_lonlat), smooth)
        lon, lat = self.frame.to_wgs84(r.xy[:, 0], r.xy[:, 1])
        lonlat = np.column_stack([lon, lat])
        lonlat[0] = start_lonlat  # the exact positions asked for, not a round trip
        lonlat[-1] = goal_lonlat
        if len(lonlat) < 2 or self.roadmap.tree is None:
            return r, lonlat
        tree, near = self.roadmap.tree, self.roadmap.clearance + FLOWN_SLACK_M

        def at_fault(readings, chords):
            fault = np.zeros(len(readings), bool)
            fault[tree.query(readings, predicate="dwithin", distance=near)[0]] = True
            return fault

        xy, lonlat = split_legs(self.frame, r.xy, lonlat, at_fault)
        clearance = float(flown_distance(tree, read_legs(self.frame, lonlat)).min())
        return dataclasses.replace(r, xy=xy, min_clearance_m=clearance), lonlat
