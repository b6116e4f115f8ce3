"""The main job as a library call: restricted features -> sites -> fences."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from alphafence.fencing.fences import FenceOptions, site_fences
from alphafence.fencing.sites import group_sites


@dataclass
class BuildOptions(FenceOptions):
    """:class:`FenceOptions` plus how sites are grouped.

    Attributes
    ----------
    join_m : float
        Features closer than this (metres) share a site.
    """

    join_m: float = 25.0


@dataclass
class BuildResult:
    """What :func:`build_fences` made.

    Attributes
    ----------
    sites : list of Site
    fences : list of Fence
        Each site's main fence, followed by its warning layer if it has one.
    seconds : dict
        Seconds per stage: ``"group"`` and ``"fence"``.
    """

    sites: list
    fences: list
    seconds: dict = field(default_factory=dict)  # stage -> seconds


def build_fences(
    features, rules, options: BuildOptions | None = None, progress=None, sites=None
) -> BuildResult:
    """Fences for every site formed by ``features`` (or for the given ``sites``).

    Parameters
    ----------
    features : list of Feature
        Restricted features, as ``read_database`` returns them.
    rules : Rules
    options : BuildOptions, optional
    progress : callable, optional
        ``progress(done, total)`` is called as sites complete (the CLI draws a bar with it).
    sites : list of Site, optional
        Sites grouped already (the comparison groups once for every method).

    Returns
    -------
    BuildResult

    Examples
    --------
    >>> import shapely
    >>> from alphafence.zones.features import Feature
    >>> from alphafence.zones.rules import load_rules
    >>> rules = load_rules()
    >>> hospital = rules.match({"amenity": "hospital"}.get, "area")
    >>> def ward(lon, source):  # a 45 m x 45 m building
    ...     box = shapely.box(lon, 35.9, lon + 0.0005, 35.9004)
    ...     return Feature(box, {"amenity": "hospital"}, source, "demo", hospital)
    >>> wards = [ward(14.5, "way/1"), ward(14.5007, "way/2"), ward(14.51, "way/3")]
    >>> result = build_fences(wards, rules)
    >>> for fence in result.fences:
    ...     print(fence.site_id, fence.kind, fence.vertices)
    hospital/way/1 keep_out 26
    hospital/way/1 warning 20
    hospital/way/3 keep_out 20
    hospital/way/3 warning 20
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
