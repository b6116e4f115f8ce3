"""Routes around keep-out fences: a reusable Voronoi roadmap, A*, line-of-sight smoothing;
and the legs of any mission checked against fences. Missions are written and read in
``alphafence.formats``."""

from alphafence.route.legs import LegIssue, check_legs
from alphafence.route.planner import FenceRoadmap, fence_label
from alphafence.route.roadmap import EPS_CLEAR, NoRoute, Roadmap, Route

__all__ = [
    "EPS_CLEAR",
    "FenceRoadmap",
    "LegIssue",
    "NoRoute",
    "Roadmap",
    "Route",
    "check_legs",
    "fence_label",
]
