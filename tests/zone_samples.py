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


def star_polygon(draw, st, reach_m, vertices, radii_m):
    """A star-shaped polygon (metric) drawn with hypothesis: a centre within ``reach_m`` of
    the origin each way, ``vertices`` (a ``(min, max)`` count) at distinct angles, each at a
    radius within ``radii_m``. It may be invalid (a vertex count of 3 with close angles):
    callers filter. ``st`` is ``hypothesis.strategies``."""
    import numpy as np

    cx, cy = draw(st.floats(-reach_m, reach_m)), draw(st.floats(-reach_m, reach_m))
    m = draw(st.integers(*vertices))
    ang = np.sort(draw(st.lists(st.floats(0, 6.28), min_size=m, max_size=m, unique=True)))
    rad = np.asarray(draw(st.lists(st.floats(*radii_m), min_size=m, max_size=m)))
    return shapely.Polygon(np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)]))
