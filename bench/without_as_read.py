"""The build without its as-read work, the named peer of what that work costs.

Importing this module takes out of the build what makes fences hold as their lon/lat
reading holds (``alphafence.fencing.as_read``): zones densified along their lon/lat edges,
margins widened by the frame's scale, fences re-simplified until they read as polygons, edges
held out by their bow and checked again as read. What is left is the build as it was before
that work. It is imported in the build's worker processes too (the forkserver preloads it).

    python -c "import sys, bench.without_as_read as w; sys.exit(w.main(sys.argv[1:]))" \
        build DB -o OUT [options]

runs ``alphafence build`` so (``bench.as_read_bench.WITHOUT_ARGV``; not ``python -m``, whose
main module the workers would run again). Only for measuring: the fences it writes hold in their metric
frames, not necessarily as read.
"""

from __future__ import annotations

from alphafence.fencing import fences, sites, tile_jobs


def _nothing_held(locals_, frames, outward=True, regions=None, zones=None):
    return list(locals_), [False] * len(locals_)


sites.densify_lonlat = lambda geoms, *a, **k: geoms
fences.ground_margins = lambda geoms, margins: list(margins)
fences.readable_fences = lambda locals_, *a, **k: list(locals_)
fences.hold_fences = _nothing_held
if "bench.without_as_read" not in tile_jobs.PRELOAD:
    tile_jobs.PRELOAD.append("bench.without_as_read")


def main(argv) -> int:
    """``alphafence`` with ``argv``, without the as-read work."""
    from alphafence.cli import main as cli

    return cli(argv)
