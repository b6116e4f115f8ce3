"""Database features -> sites -> fences.

:data:`METHODS` lives here, not in :mod:`alphafence.build.fences`, so that the command line
can offer the methods without importing the geometry stack.
"""

METHODS = ("alpha", "polygon", "circle", "exact")
