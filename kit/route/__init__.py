"""Routes around keep-out fences: a reusable Voronoi roadmap, A*, line-of-sight smoothing,
and missions (QGC .plan / QGC WPL 110) that fly them; legs of any mission checked against
fences."""

from kit.route.fenceroute import FenceRoadmap, fence_label
from kit.route.mission import check_legs, mission_items, mission_waypoints_text, read_mission
from kit.route.roadmap import EPS_CLEAR, NoRoute, Roadmap, Route

__all__ = [
    "EPS_CLEAR",
    "FenceRoadmap",
    "NoRoute",
    "Roadmap",
    "Route",
    "check_legs",
    "fence_label",
    "mission_items",
    "mission_waypoints_text",
    "read_mission",
]
