"""Zones -> sites -> fences: grouping, alpha shapes and the other methods, fences held as
read in lon/lat, country-scale builds in tiles and worker processes, outputs, bundles.

:data:`METHODS` lives here, not in :mod:`alphafence.fencing.fences`, so that the command line
can offer the methods without importing the geometry stack.
"""

METHODS = ("alpha", "polygon", "circle", "exact")
