"""In-flight re-routing around keep-out fences (``--imminent-action reroute``).

A :class:`Rerouter` plans as ``alphafence route`` does (``alphafence.route.CorridorPlanner``): a
roadmap over only the fences in a corridor around the vehicle and its goal, widened while the
route comes too close to a fence left out, so that a national fence file costs no more than
the fences near the flight. The fences are read (edges straight in lon/lat, as ArduPilot
reads them) into a frame near the vehicle, kept while the vehicle and its goals stay within
``VIEW_REUSE_M`` of its origin. It is made when the monitor starts (``await
Rerouter.build(...)``, in a worker thread), and every query is independent, so the monitor
plans in a worker thread too and never blocks the event loop. The legs of a plan are flown as
ArduPilot flies them, straight in lon/lat: legs whose lon/lat line would come too close to a
fence are split (:func:`alphafence.route.planner.split_legs`) and the clearance is that of the
legs as flown.

This module holds the planning; :mod:`alphafence.monitor.reroute_flight` flies the plans. The
pieces it needs are pure functions of positions, velocities and fences, tested without
MAVSDK:

* :func:`goal_beyond_xy` - with no known target, the goal is the first point along the current
  track, beyond the fence ahead, that is clear of every keep-out by the clearance;
* :meth:`Rerouter.plan` - the route from where the vehicle can stop to the goal, as the list of
  waypoints to fly (:func:`waypoints`: ``(lat, lon)`` rounded to 1e-7 degrees);
* :func:`mission_goal` and :func:`parse_position_target` - the vehicle's own goal: the AUTO
  mission item it is flying to, or its GUIDED target (POSITION_TARGET_GLOBAL_INT);
* :func:`leg_timeout_s` - how long one leg may take before the re-route is given up.

The planner treats every keep-out fence as a wall from the ground up, whatever its altitude
limits or time windows: a re-route never relies on flying over a zone or on its hours.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.awareness.predict import Braking
from alphafence.errors import RoutingError
from alphafence.geo.coords import from_e7_float
from alphafence.geo.frame import EARTH_RADIUS_M, LocalFrame
from alphafence.mavlink import ids
from alphafence.route.planner import fence_label, flown_distance, read_legs
from alphafence.route.roadmap import NoRoute
from alphafence.vehicle.values import fields_of

GOAL_SEARCH_M = 5000.0  # how far along the track to look for the far side of a fence
GOAL_PAD_M = 1.0  # the goal lies this much beyond the clearance (the vehicle hovers there)
LEAD_STEP_M = 2.0
LEG_MIN_SPEED_MPS = 2.0  # a leg taking longer than at this speed (plus slack) has failed
LEG_SLACK_S = 20.0
VIEW_REUSE_M = 50_000.0  # fences read into a frame serve positions this close to its origin
# mission item frames whose x, y are latitude, longitude (1e-7 degrees in MISSION_ITEM_INT)
GLOBAL_FRAMES = frozenset(
    {
        ids.MAV_FRAME_GLOBAL,
        ids.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        ids.MAV_FRAME_GLOBAL_INT,
        ids.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        ids.MAV_FRAME_GLOBAL_TERRAIN_ALT,
        ids.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
    }
)


class RerouteFailed(RoutingError):
    """A re-route that cannot be flown: ``str(err)`` is the one-line reason."""


@dataclass
class Plan:
    """A re-route, ready to fly."""

    waypoints: list  # [(lat, lon)], rounded to 1e-7 degrees, the goal last
    goal: tuple  # (lon, lat)
    start: tuple  # (lon, lat) where the planned route begins (see Rerouter.plan)
    length_m: float  # from the vehicle through every waypoint
    clearance_m: float  # exact least distance of those legs to any keep-out fence


def waypoints(lonlat, skip_start: bool = True) -> list:
    """A route's vertices ((n, 2) lon, lat) as the waypoints to fly: (lat, lon) rounded to
    1e-7 degrees (about 1 cm, MAVLink's integer resolution), the start left out."""
    pts = np.asarray(lonlat, float).reshape(-1, 2)
    if skip_start:
        pts = pts[1:]
    return [(round(float(lat), 7), round(float(lon), 7)) for lon, lat in pts]


def leg_timeout_s(length_m: float) -> float:
    """Seconds one leg may take: its length at a crawl, plus slack for turning and stopping."""
    return LEG_SLACK_S + max(0.0, float(length_m)) / LEG_MIN_SPEED_MPS


def planning_lead_m(speed_mps: float, braking: Braking) -> float:
    """How far along its track the vehicle gets before a new target takes effect: the
    monitor's stopping distance (reaction plus braking) without the safety margin."""
    v = max(0.0, float(speed_mps))
    return v * braking.reaction_s + v * v / (2.0 * braking.decel_mps2)


def parse_position_target(fields):
    """POSITION_TARGET_GLOBAL_INT fields (a dict, or JSON text) -> (lon, lat), or None
    when the message carries no horizontal position."""
    try:
        f = fields_of(fields)
        lat, lon = from_e7_float(f["lat_int"]), from_e7_float(f["lon_int"])
        mask = int(f.get("type_mask", 0))
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    if (
        mask & ids.POSITION_TARGET_TYPEMASK_X_IGNORE
        and mask & ids.POSITION_TARGET_TYPEMASK_Y_IGNORE
    ):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return (lon, lat)


def mission_goal(items, current: int):
    """The position (lon, lat) of mission item ``current`` (MAVSDK mission_raw items, seq as
    ArduPilot numbers them, home at 0), or None if it has none (RTL, a DO command, a takeoff
    or landing where the vehicle is)."""
    item = next((it for it in items if int(it.seq) == int(current)), None)
    if item is None or int(item.command) not in ids.NAV_POSITION_COMMANDS:
        return None
    if int(item.frame) not in GLOBAL_FRAMES or (item.x == 0 and item.y == 0):
        return None
    lat, lon = from_e7_float(item.x), from_e7_float(item.y)
    if not (abs(lat) <= 90 and abs(lon) <= 180):
        return None
    return (lon, lat)


def goal_beyond_xy(roadmap, start_xy, direction_xy, max_m=GOAL_SEARCH_M, pad_m=GOAL_PAD_M):
    """The first point along the ray from ``start_xy`` in ``direction_xy`` (metres in the
    roadmap's frame) that lies beyond a keep-out fence's clearance band and is clear of every
    keep-out by the clearance (plus ``pad_m``); None if the ray meets no fence, or ends
    inside one, within ``max_m``. ``roadmap`` is a :class:`~alphafence.route.Roadmap` or a
    :class:`~alphafence.route.corridor.FenceView`: its ``tree``, ``keep_out``, ``ce`` and
    ``point_clear``."""
    p = np.asarray(start_xy, float).reshape(2)
    d = np.asarray(direction_xy, float).reshape(2)
    norm = float(np.hypot(*d))
    if roadmap.tree is None or not math.isfinite(norm) or norm < 1e-9:
        return None
    u = d / norm
    ray = shapely.LineString([p, p + u * max_m])
    band = roadmap.ce + pad_m
    near = roadmap.tree.query(ray, predicate="dwithin", distance=band)
    if not np.size(near):
        return None
    blocked = shapely.union_all(shapely.buffer(roadmap.keep_out[near], band, quad_segs=16))
    free = shapely.get_parts(shapely.difference(ray, blocked))
    starts = sorted(ray.project(shapely.Point(g.coords[0])) for g in free if not g.is_empty)
    for along in starts:
        if along <= 1e-6:  # the stretch the vehicle is in now, before the fence
            continue
        # the band is a polygon inscribed in the true offset curve: step on until the exact
        # distance test agrees
        for extra in np.arange(0.0, 50.0, 0.5):
            q = p + u * min(along + extra, max_m)
            if roadmap.point_clear(q)[0]:
                return q
        return None
    return None


class Rerouter:
    """The route planner over the monitor's fences (see :meth:`build`): each plan over the
    fences in a corridor around the vehicle and its goal.

    Parameters
    ----------
    records : list of FenceRecord
    clearance : float
        Least distance of a re-route from any keep-out fence, metres.
    """

    def __init__(self, records, clearance: float = 20.0):
        self.records = list(records)
        self.clearance = float(clearance)
        self.view = None  # the fences read into a frame near the vehicle (see view_for)
        # what the first plan would otherwise import while the vehicle flies at the fence
        # (scipy.spatial alone takes a third of a second, 15 m at 10 m/s and speedup 5):
        # here, in the worker thread that builds the planner when the monitor starts
        from alphafence.route import corridor  # noqa: F401

        with contextlib.suppress(ImportError):  # without it, planning fails as it did
            import scipy.spatial  # noqa: F401

    @classmethod
    async def build(cls, records, clearance: float = 20.0) -> Rerouter:
        """Build in a worker thread: the event loop (the monitor's checks) never waits."""
        return await asyncio.to_thread(cls, records, clearance)

    def view_for(self, *lonlat):
        """The fences read into a frame that serves every ``(lon, lat)`` given: the last one,
        when they are all within ``VIEW_REUSE_M`` of its origin, else a new one centred on
        them (:class:`~alphafence.route.corridor.FenceView`)."""
        from alphafence.route.corridor import FenceView

        pts = np.asarray(lonlat, float).reshape(-1, 2)
        view = self.view
        if view is not None:
            x, y = view.frame.to_local(pts[:, 0], pts[:, 1])
            if np.all(np.hypot(x, y) <= VIEW_REUSE_M):
                return view
        self.view = FenceView(self.records, LocalFrame.around_coords(pts), self.clearance)
        return self.view

    def _velocity_xy(self, view, lon, lat, ve, vn) -> np.ndarray:
        """East/north velocity as a direction in the view's frame (the frame's grid north is
        not true north away from its origin)."""
        p = view.to_xy((lon, lat))
        dlat = vn / EARTH_RADIUS_M * 180.0 / math.pi
        dlon = ve / (EARTH_RADIUS_M * max(math.cos(math.radians(lat)), 1e-6)) * 180.0 / math.pi
        return view.to_xy((lon + dlon, lat + dlat)) - p

    def goal_beyond(self, lon, lat, ve, vn, max_m=GOAL_SEARCH_M):
        """(lon, lat) beyond the fence ahead along the track, or None."""
        if math.hypot(ve, vn) < 0.5:
            return None  # no track to follow
        view = self.view_for((lon, lat))
        q = goal_beyond_xy(
            view, view.to_xy((lon, lat)), self._velocity_xy(view, lon, lat, ve, vn), max_m
        )
        return None if q is None else view.to_lonlat(q)

    @staticmethod
    def start_xy(view, xy, direction_xy, lead_m: float) -> np.ndarray:
        """Where the planned route begins: ``lead_m`` along the track (where the vehicle will
        be by the time it turns: it cannot turn on the spot), pulled back until that point and
        the track to it are clear; the vehicle's position if no such point is."""
        xy = np.asarray(xy, float).reshape(2)
        d = np.asarray(direction_xy, float).reshape(2)
        norm = float(np.hypot(*d))
        if lead_m <= 0 or norm < 1e-9:
            return xy
        u = d / norm
        for ahead in np.arange(float(lead_m), 0.0, -LEAD_STEP_M):
            q = xy + u * ahead
            if view.point_clear(q)[0] and view.clear(xy, q)[0]:
                return q
        return xy

    def plan(self, lon, lat, ve, vn, goal_lonlat, lead_m: float = 0.0) -> Plan:
        """The re-route from the vehicle at (lon, lat) moving at (ve, vn) m/s to ``goal_lonlat``.
        Raises ``NoRoute`` with the planner's one-line reason."""
        from alphafence.route.corridor import CorridorPlanner

        view = self.view_for((lon, lat), goal_lonlat)
        here = view.to_xy((lon, lat))
        start = self.start_xy(view, here, self._velocity_xy(view, lon, lat, ve, vn), lead_m)
        start_lonlat = (lon, lat) if np.allclose(start, here) else view.to_lonlat(start)
        planner = CorridorPlanner(None, start_lonlat, goal_lonlat, view=view)
        _, lonlat = planner.route()
        # the vehicle flies from where it is to the first vertex past the planned start when
        # that leg, as flown, is clear, else through the planned start itself
        first = 1 if len(lonlat) > 1 else 0
        if first and not np.allclose(start, here):
            ahead = view.to_xy(lonlat[1])
            reading = read_legs(view.frame, [(lon, lat), lonlat[1]])
            chord = shapely.linestrings([[here, ahead]])
            if not view.clear(here, ahead)[0] or view.at_fault(reading, chord)[0]:
                first = 0
        flown = np.vstack([(lon, lat), lonlat[first:]])
        legs = read_legs(view.frame, flown)
        self._check_keep_in(view, here, legs)
        xy = np.column_stack(view.frame.to_local(flown[:, 0], flown[:, 1]))
        length = float(np.hypot(*np.diff(xy, axis=0).T).sum())
        clearance = float(flown_distance(view.tree, legs).min()) if len(legs) else math.inf
        return Plan(
            waypoints=waypoints(lonlat[first:], skip_start=False),
            goal=(float(goal_lonlat[0]), float(goal_lonlat[1])),
            start=start_lonlat,
            length_m=length,
            clearance_m=clearance,
        )

    @staticmethod
    def _check_keep_in(view, here, legs):
        """NoRoute when the legs (as flown) leave a keep-in fence the vehicle is in."""
        p = shapely.Point(here)
        path = shapely.union_all(legs) if len(legs) else p
        for poly, record in zip(view.keep_in, view.keep_in_records):
            if poly.covers(p) and not poly.covers(path):
                raise NoRoute(
                    f"the route around the keep-out leaves keep-in fence {fence_label(record)}"
                )
