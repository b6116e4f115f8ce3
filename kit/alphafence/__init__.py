"""AlphaFence: tight, safe alpha-shape geofences for ArduPilot vehicles.

The library works without the command line::

    from alphafence import load_rules, read_database, build_fences, BuildOptions
    rules = load_rules()
    db = read_database(["malta.osm.pbf"], rules)
    result = build_fences(db.features, rules, BuildOptions(method="alpha"))

The package is layered by the stages data flows through, each importing only the ones below:

=============  ==============================================================================
``errors``     the one error hierarchy
``geo``        local metric frames, coordinate order, alpha shapes, outward simplification
``mavlink``    MAVLink numbers, fence items and what they cost in fence storage
``formats``    every file format, read and written: OSM, GeoJSON, ED-269, rules, QGC plans, WPL
``build``      database features -> sites -> fences; comparison; signed bundles
``onboard``    fences -> the items a vehicle's fence storage holds
``route``      the Voronoi roadmap, routes around fences, mission legs
``vehicle``    the MAVLink link (MAVSDK, signing bridge), fence transfer, parameters
``sitl``       finding and running ArduPilot SITL
``monitor``    the in-flight companion: engine, feeds, actions, runner
``plots``      pictures of fences, comparisons and routes
``cli``        the ``alphafence`` command, one verb per module
=============  ==============================================================================

Importing ``alphafence`` loads nothing but this file: the names below load their stage on
first use.
"""

__version__ = "0.1.0"

_EXPORTS = {
    "BuildOptions": "alphafence.build.pipeline",
    "build_fences": "alphafence.build.pipeline",
    "build_tiled": "alphafence.build.tiled",
    "read_database": "alphafence.formats.database",
    "DatabaseStream": "alphafence.formats.database",
    "load_rules": "alphafence.formats.rules",
}

__all__ = [*_EXPORTS, "__version__"]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'alphafence' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
