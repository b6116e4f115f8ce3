"""AlphaFence: tight, safe alpha-shape geofences for ArduPilot vehicles.

The library works without the command line::

    from kit import load_rules, read_database, build_fences, BuildOptions
    rules = load_rules()
    db = read_database(["malta.osm.pbf"], rules)
    result = build_fences(db.features, rules, BuildOptions(method="alpha"))
"""

__version__ = "0.1.0"

from kit.build import BuildOptions, build_fences  # noqa: E402
from kit.readers import read_database  # noqa: E402
from kit.rules import load_rules  # noqa: E402

__all__ = ["BuildOptions", "build_fences", "load_rules", "read_database", "__version__"]
