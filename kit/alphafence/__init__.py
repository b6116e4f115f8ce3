"""AlphaFence: tight, safe alpha-shape geofences for ArduPilot vehicles.

The library works without the command line::

    from alphafence import load_rules, read_database, build_fences, BuildOptions
    rules = load_rules()
    db = read_database(["malta.osm.pbf"], rules)
    result = build_fences(db.features, rules, BuildOptions(method="alpha"))

The package is layered by the stages data flows through, each importing only the ones below:

==============  =============================================================================
``errors``      the one error hierarchy
``geo``         local metric frames, coordinate order, alpha shapes, outward simplification
``mavlink``     MAVLink numbers, fence items and what they cost in fence storage
``zones``       where zones come from: OSM, GeoJSON, ED-269/ED-318, KML, OpenAir; the rules
``fencefiles``  the kit's fence files: fence GeoJSON, GeoParquet, QGC plans, WPL, written safely
``fencing``     zones -> sites -> fences; country-scale builds; comparison; signed bundles
``flights``     missions and flight logs (DataFlash, tlog)
``onboard``     fences -> the items a vehicle's fence storage holds
``route``       the Voronoi roadmap, routes around fences, mission legs
``awareness``   the monitor's surroundings, without I/O: fences indexed, traffic, predictions
``vehicle``     the MAVLink link (MAVSDK, signing bridge), fence transfer, parameters
``sitl``        finding and running ArduPilot SITL
``monitor``     the in-flight companion: engine, feeds, actions, rolling uploads, runner
``plots``       pictures of fences, comparisons and routes; interactive HTML maps
``review``      flights and missions checked away from the vehicle; recorded flights replayed
``livemap``     the live map: its observer, messages, web server and page
``cli``         the ``alphafence`` command, one verb per module
==============  =============================================================================

Importing ``alphafence`` loads nothing but this file: the names below load their stage on
first use.
"""

__version__ = "0.1.0"

_EXPORTS = {
    "BuildOptions": "alphafence.fencing.pipeline",
    "build_fences": "alphafence.fencing.pipeline",
    "build_tiled": "alphafence.fencing.tiled",
    "read_database": "alphafence.zones.database",
    "DatabaseStream": "alphafence.zones.database",
    "load_rules": "alphafence.zones.rules",
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
