"""Zones as the kit reads them, for tests that hold its outputs to the autopilot models
(``tests/ardupilot_model.py``, which shares no code with the kit)."""

from __future__ import annotations

import shapely


def zone_features(zones, rules, name="zones.geojson"):
    """Lon/lat polygons as the restricted features of a GeoJSON FeatureCollection, the ``k``th
    with ``osm_id`` ``k`` (its source ends ``/k``), read with ``rules``."""
    import collections

    from alphafence.zones.geojson import read_geojson_doc

    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"restricted": "yes", "osm_id": str(k)},
                "geometry": shapely.geometry.mapping(z),
            }
            for k, z in enumerate(zones)
        ],
    }
    return read_geojson_doc(name, doc, rules, [], collections.Counter())
