"""Routes around keep-out fences: a reusable Voronoi roadmap, A*, line-of-sight smoothing, a
corridor planner that builds the roadmap over only the fences near start and goal; and the
legs of any mission checked against fences. Missions are read in
``alphafence.flights``."""

from alphafence.route.corridor import Corridor, CorridorPlanner, FenceView
from alphafence.route.legs import LegIssue, check_legs
from alphafence.route.planner import FenceRoadmap, fence_label
from alphafence.route.roadmap import EPS_CLEAR, NoRoute, Roadmap, Route

__all__ = [
    "EPS_CLEAR",
    "Corridor",
    "CorridorPlanner",
    "FenceView",
    "FenceRoadmap",
    "LegIssue",
    "NoRoute",
    "Roadmap",
    "Route",
    "check_legs",
    "fence_label",
]
