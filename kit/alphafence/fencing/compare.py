"""The paper's evaluation: alpha-shape fences against polygonal, circular and exact fences."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.sites import group_sites


@dataclass
class MethodStats:
    """How one method's fences fare over every site.

    Attributes
    ----------
    method : str
    sites : int
    containment_pct : float
        Share of the restricted area inside its fences, % (must be 100).
    overshoot : float
        Fence area outside the restricted area, over the restricted area.
    excess : float
        Fence area outside the restricted area grown by its margin, over the restricted area.
    vertices_median, vertices_p95 : float
        Vertices a fence (1 for a circle).
    vertices_total : int
    seconds : float
        Time to group and fence every site.
    """

    method: str
    sites: int
    containment_pct: float  # % of the restricted area inside its fences (must be 100)
    overshoot: float  # fence area outside the restricted area / restricted area
    excess: float  # fence area outside restricted area + margin / restricted area
    vertices_median: float
    vertices_p95: float
    vertices_total: int
    seconds: float

    def as_dict(self):
        """The statistics as a plain dict (for ``--json``)."""
        return dataclasses.asdict(self)


@dataclass
class Comparison:
    """The methods compared on the same sites.

    Attributes
    ----------
    sites : list of Site
    stats : list of MethodStats
        One per method, in the order asked.
    fences : dict
        ``{method: {site_id: main Fence}}``.
    group_seconds : float
        Time to group the sites (once, for every method).
    """

    sites: list
    stats: list
    fences: dict  # method -> {site_id: main fence}
    group_seconds: float


def main_fences(result):
    """``{site_id: Fence}``: each site's main fence (the one of the site's own kind, not its
    warning layer) in a :class:`BuildResult`."""
    kinds = {s.site_id: s.kind for s in result.sites}
    return {f.site_id: f for f in result.fences if f.kind == kinds[f.site_id]}


def method_stats(method, sites, fences, seconds) -> MethodStats:
    """:class:`MethodStats` of one method's main fences (``{site_id: Fence}``) on ``sites``."""
    geoms = np.array([s.geometry for s in sites], dtype=object)
    local = np.array([fences[s.site_id].local for s in sites], dtype=object)
    margins = np.array([fences[s.site_id].margin_m for s in sites])
    g_area = shapely.area(geoms)
    inside = shapely.area(shapely.intersection(local, geoms))
    f_area = np.array([fences[s.site_id].area_m2 for s in sites])
    with_margin = shapely.buffer(geoms, margins, quad_segs=8)
    beyond = f_area - shapely.area(shapely.intersection(local, with_margin))
    verts = np.array([fences[s.site_id].vertices for s in sites])
    total = g_area.sum()
    return MethodStats(
        method=method,
        sites=len(sites),
        containment_pct=float(100.0 * inside.sum() / total) if total else 100.0,
        overshoot=float((f_area - inside).sum() / total) if total else 0.0,
        excess=float(np.maximum(beyond, 0).sum() / total) if total else 0.0,
        vertices_median=float(np.median(verts)),
        vertices_p95=float(np.percentile(verts, 95)),
        vertices_total=int(verts.sum()),
        seconds=seconds,
    )


def compare_methods(
    features, rules, methods, options: BuildOptions | None = None, progress=None
) -> Comparison:
    """Build every site's fences with each method, on sites grouped once.

    Warning layers are left out; every method gets the same ``options`` otherwise.

    Parameters
    ----------
    features : list of Feature
    rules : Rules
    methods : sequence of str
        E.g. ``METHODS``.
    options : BuildOptions, optional
    progress : callable, optional
        ``progress(done, total)`` after each method.

    Returns
    -------
    Comparison
    """
    options = options or BuildOptions()
    t0 = time.perf_counter()
    sites = group_sites(features, rules, options.join_m)
    group_seconds = time.perf_counter() - t0
    stats, fences = [], {}
    for k, method in enumerate(methods):
        opts = dataclasses.replace(options, method=method, warn_distance_m=0.0)
        t = time.perf_counter()
        result = build_fences(features, rules, opts, sites=sites)
        seconds = time.perf_counter() - t + group_seconds
        fences[method] = main_fences(result)
        stats.append(method_stats(method, sites, fences[method], seconds))
        if progress:
            progress(k + 1, len(methods))
    return Comparison(sites, stats, fences, group_seconds)


def telling_sites(comparison, count=3):
    """Sites where the methods differ most: where alpha saves the most area over polygon."""
    f = comparison.fences
    a = f.get("alpha")
    b = f.get("polygon") or f.get("circle")
    sites = [s for s in comparison.sites if s.geometry.area > 0]
    if a and b:
        sites.sort(
            key=lambda s: (
                -(b[s.site_id].area_m2 - a[s.site_id].area_m2)
                / max(b[s.site_id].area_m2, 1.0)
                * np.sqrt(s.geometry.area)
            )
        )
    else:
        sites.sort(key=lambda s: -s.geometry.area)
    return sites[:count]
