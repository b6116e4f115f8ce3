"""The main job as a library call: restricted features -> sites -> fences."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from alphafence.build.fences import FenceOptions, site_fences
from alphafence.build.sites import group_sites


@dataclass
class BuildOptions(FenceOptions):
    join_m: float = 25.0


@dataclass
class BuildResult:
    sites: list
    fences: list
    seconds: dict = field(default_factory=dict)  # stage -> seconds


def build_fences(
    features, rules, options: BuildOptions | None = None, progress=None, sites=None
) -> BuildResult:
    """Fences for every site formed by ``features`` (or for the given ``sites``).

    ``progress(done, total)`` is called as sites complete (the CLI draws a bar with it).
    """
    options = options or BuildOptions()
    t0 = time.perf_counter()
    if sites is None:
        sites = group_sites(features, rules, options.join_m)
    t1 = time.perf_counter()
    fences = []
    for i, site in enumerate(sites):
        fences.extend(site_fences(site, options))
        if progress is not None:
            progress(i + 1, len(sites))
    t2 = time.perf_counter()
    return BuildResult(sites, fences, {"group": t1 - t0, "fence": t2 - t1})
