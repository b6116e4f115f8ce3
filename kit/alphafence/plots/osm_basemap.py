"""A basemap drawn offline from an OpenStreetMap extract: roads, water and place names, for the
live map where there are no map tiles (a vehicle in the field has no internet).

Read through pyosmium (only the objects with the keys drawn), within a lon/lat box, simplified
to what a map at street scale shows, as one GeoJSON FeatureCollection whose features carry a
``layer`` (``road``, ``water``, ``place``) and, for roads and places, a ``class`` and a
``name``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely

from alphafence.errors import InputError, need

ROADS = {"motorway", "trunk", "primary", "secondary", "tertiary", "unclassified", "residential"}
PLACES = {"city", "town", "village", "suburb", "hamlet", "neighbourhood"}
WATER_AREAS = {"water", "bay"}
SIMPLIFY_DEG = 0.00003  # about 3 m: a street-scale map does not show less
MAX_FEATURES = 60_000  # a page gets at most this many (roads of the lowest classes go first)


def osm_basemap(path, bbox) -> dict:
    """The roads, water and place names of an OSM extract within ``bbox``.

    Parameters
    ----------
    path : str or Path
        An OpenStreetMap extract (``.osm.pbf``, ``.osm``).
    bbox : tuple
        ``(min lon, min lat, max lon, max lat)``.

    Returns
    -------
    dict
        A GeoJSON FeatureCollection (``properties.layer``: road, water or place).

    Raises
    ------
    InputError
        No such file, or not readable as OSM.
    """
    need(("osmium.filter", f"reading {path}"))
    import osmium
    from osmium.filter import KeyFilter

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    box = shapely.box(*bbox)
    wkb = osmium.geom.WKBFactory()
    blobs, props = [], []
    keys = ("highway", "natural", "waterway", "place")
    try:
        fp = (osmium.FileProcessor(str(path)).with_locations()
              .with_areas(KeyFilter("natural")).with_filter(KeyFilter(*keys)))  # fmt: skip
        for obj in fp:
            what = _what(obj)
            if what is None:
                continue
            try:
                if obj.is_area():
                    blob = wkb.create_multipolygon(obj)
                elif obj.is_node():
                    blob = wkb.create_point(obj)
                else:
                    blob = wkb.create_linestring(obj)
            except (osmium.InvalidLocationError, RuntimeError):
                continue
            blobs.append(blob)
            props.append(what)
    except (RuntimeError, ValueError, OSError) as exc:
        raise InputError(path, f"not a readable OSM file ({exc})") from None
    geoms = shapely.from_wkb(np.array(blobs, dtype=object)) if blobs else np.array([])
    keep = shapely.intersects(geoms, box) if len(geoms) else np.array([], dtype=bool)
    geoms = shapely.simplify(shapely.intersection(geoms[keep], box), SIMPLIFY_DEG)
    props = [p for p, k in zip(props, keep) if k]
    order = sorted(range(len(props)), key=lambda k: _rank(props[k]))[:MAX_FEATURES]
    features = [
        {"type": "Feature", "properties": props[k], "geometry": shapely.geometry.mapping(geoms[k])}
        for k in sorted(order)
        if not geoms[k].is_empty
    ]
    return {"type": "FeatureCollection", "features": features}


def _what(obj) -> dict | None:
    """What an OSM object is on the basemap, or None."""
    tags = obj.tags
    name = tags.get("name")
    if obj.is_relation():
        return None
    if obj.is_node():
        place = tags.get("place")
        return (
            {"layer": "place", "class": place, "name": name} if place in PLACES and name else None
        )
    if obj.is_area():
        if tags.get("natural") in WATER_AREAS:
            return {"layer": "water"}
        return None
    highway = tags.get("highway")
    if highway in ROADS:
        return {"layer": "road", "class": highway, "name": name}
    if tags.get("natural") == "coastline" or tags.get("waterway") in ("river", "canal"):
        return {"layer": "water"}
    return None


def _rank(props) -> int:
    """Which features a page gets first when there are too many: places, water, main roads."""
    order = ["motorway", "trunk", "primary", "secondary", "tertiary", "unclassified", "residential"]
    if props["layer"] != "road":
        return 0
    return 1 + order.index(props["class"])


def around(records, pad_deg: float = 0.1) -> tuple:
    """The lon/lat box of fence ``records``, widened by ``pad_deg`` (about 10 km).

    Examples
    --------
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> around([FenceRecord("a", "keep_out", shapely.box(14.5, 35.9, 14.6, 36.0))])
    (14.4, 35.8, 14.7, 36.1)
    """
    b = shapely.total_bounds([r.geometry for r in records])
    b = [float(v) for v in b]
    return (round(max(-180.0, b[0] - pad_deg), 9), round(max(-90.0, b[1] - pad_deg), 9),
            round(min(180.0, b[2] + pad_deg), 9), round(min(90.0, b[3] + pad_deg), 9))  # fmt: skip
