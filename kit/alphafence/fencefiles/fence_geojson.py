"""The kit's fence GeoJSON: written by ``alphafence build``, read back by compile, upload,
monitor and route.

A FeatureCollection (RFC 7946, lon/lat) with one Feature per fence; the properties carry the
site, kind, method, margin and altitude band (see ``fence_properties``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence import __version__
from alphafence.errors import InputError
from alphafence.fencefiles.fence_text import (
    FenceFeatures,
    paused_gc,
    ring_structure,
    wgs84_coordinates,
)
from alphafence.mavlink.items import exterior_vertices
from alphafence.zones.features import check_coordinates
from alphafence.zones.jsonfile import read_json
from alphafence.zones.mistakes import database_message

KINDS = ("keep_out", "keep_in", "warning")


@dataclass
class FenceRecord:
    """A fence as read back from the kit's fence GeoJSON (WGS84).

    Attributes
    ----------
    site_id : str
        ``"<category>/<source>"``, e.g. ``"hospital/way/1005"``.
    kind : str
        ``"keep_out"``, ``"keep_in"`` or ``"warning"``.
    geometry : shapely.Polygon or shapely.MultiPolygon
        Lon, lat.
    margin_m : float
        The margin the fence keeps around the restricted area.
    name, category : str, optional
    alt_min_m, alt_max_m : float, optional
        The altitude band it applies to (None: unbounded).
    circle : tuple, optional
        ``(lon, lat, radius_m)`` of a circle fence.
    properties : dict
        Every property of the feature, as written.

    Examples
    --------
    >>> import shapely
    >>> fence = FenceRecord("hospital/way/1", "keep_out", shapely.box(14.5, 35.9, 14.501, 35.901))
    >>> fence.kind, fence.margin_m, fence.circle
    ('keep_out', 0.0, None)
    """

    site_id: str
    kind: str
    geometry: object  # WGS84 Polygon / MultiPolygon
    margin_m: float = 0.0
    name: str | None = None
    category: str | None = None
    alt_min_m: float | None = None
    alt_max_m: float | None = None
    circle: tuple | None = None  # (lon, lat, radius_m)
    properties: dict = field(default_factory=dict)


def fence_record(path, props, geometry, label, index):
    """One fence from its properties and shapely geometry, checked as every
    fence reader checks a feature (kind, polygonal geometry, a circle's centre and radius).

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    props : dict
    geometry : shapely geometry or None
    label : str
        The feature as messages name it (``"record 3 (hospital/way/1)"``).
    index : int
        Its place in the file: ``site_id`` is ``"fence/<index>"`` when it has none.

    Returns
    -------
    FenceRecord
    """
    kind = _kind_of(path, props, label)
    gtype = getattr(geometry, "geom_type", None)
    if gtype not in ("Polygon", "MultiPolygon"):
        raise InputError(path, f"a fence must be a Polygon or MultiPolygon, not {gtype}", label)
    circle = None
    if "radius_m" in props:
        c, r = props.get("center"), props.get("radius_m")
        if not (isinstance(c, list) and len(c) == 2 and isinstance(r, (int, float)) and r > 0):
            raise InputError(
                path, "circle fence needs center [lon, lat] and a positive radius_m", label
            )
        circle = (float(c[0]), float(c[1]), float(r))
    return FenceRecord(
        site_id=str(props["site_id"] if props.get("site_id") is not None else f"fence/{index}"),
        kind=kind,
        geometry=geometry,
        margin_m=float(props.get("margin_m") or 0.0),
        name=props.get("name"),
        category=props.get("category"),
        alt_min_m=props.get("alt_min_m"),
        alt_max_m=props.get("alt_max_m"),
        circle=circle,
        properties=props,
    )


def _kind_of(path, props, label):
    kind = props.get("kind")
    if kind not in KINDS:
        kinds = ", ".join(KINDS)
        raise InputError(path, f"kind must be one of {kinds}, not {kind!r}", label)
    return kind


def _refuse_zone_list(path, doc):
    """An ED-269 or ED-318 geozone list where fences belong: say to build fences of it."""
    from alphafence.zones.ed269 import looks_like_ed269
    from alphafence.zones.ed318 import looks_like_ed318

    if looks_like_ed269(doc) or looks_like_ed318(doc):
        raise InputError(path, database_message(path, "an ED-269/ED-318 geozone list", ".json"))


def read_fences(path) -> list:
    """The fences of a fence GeoJSON file written by ``alphafence build``.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of FenceRecord

    Raises
    ------
    InputError
        A one-line message naming the feature that is malformed (not a FeatureCollection,
        unknown kind, a geometry that is not a polygon, coordinates out of range).
    """
    doc = read_json(path)
    if (
        not isinstance(doc, dict)
        or doc.get("type") != "FeatureCollection"
        or not isinstance(doc.get("features"), list)
    ):
        _refuse_zone_list(path, doc)
        raise InputError(path, "not a fence GeoJSON FeatureCollection")
    out = []
    for i, feat in enumerate(doc["features"]):
        props = feat.get("properties") if isinstance(feat, dict) else None
        if not isinstance(props, dict):
            raise InputError(path, "feature without properties", f"feature {i}")
        if i == 0 and "kind" not in props and "site_id" not in props:
            # map features (OSM tags, ED-318 zones): what build reads, not what it writes
            _refuse_zone_list(path, doc)
            raise InputError(path, database_message(path, "GeoJSON map features", ".geojson"))
        label = f"feature {i} ({props.get('site_id', '?')})"
        _kind_of(path, props, label)  # before the geometry
        try:
            geom = shapely.geometry.shape(feat.get("geometry"))
        except (
            ShapelyError,
            ValueError,
            TypeError,
            AttributeError,
            KeyError,
            IndexError,
        ) as exc:
            raise InputError(path, f"malformed geometry ({exc})", label) from None
        out.append(fence_record(path, props, geom, label, i))
    if out:
        check_coordinates(
            path, np.array([f.geometry for f in out], dtype=object), lambda k: out[k].site_id
        )
    return out


# -- writing ----------------------------------------------------------------------------
DECIMALS = 8  # 1e-8 degrees is about 1 mm; fences carry 0.1 m of slack for it


def fence_properties(f) -> dict:
    """The GeoJSON properties of a built fence (``build.fences.Fence``): site, name,
    category, kind, method, margin, altitude band, vertices, area and sources; ``alpha_m``,
    ``center`` and ``radius_m`` for circles, ``repaired`` and the ED-269 ``zone`` when they
    apply."""
    return _properties(f, f.vertices, f.area_m2)


def fence_numbers(fences) -> tuple:
    """The ``vertices`` and ``area_m2`` of built fences, the numbers their own properties
    give, counted and measured all at once.

    Parameters
    ----------
    fences : list of Fence

    Returns
    -------
    (list of int, list of float)
    """
    fences = list(fences)
    local = np.empty(len(fences), dtype=object)
    local[:] = [f.local for f in fences]
    if any(g is None for g in local):
        return [f.vertices for f in fences], [f.area_m2 for f in fences]
    vertices = exterior_vertices(local).tolist()
    areas = shapely.area(local).tolist()
    for k, f in enumerate(fences):
        if f.circle is not None:  # as Fence.vertices and Fence.area_m2 have it
            vertices[k], areas[k] = 1, math.pi * f.circle[2] ** 2
    return vertices, areas


def _properties(f, vertices, area_m2):
    props = {
        "site_id": f.site_id,
        "name": f.name,
        "category": f.category,
        "kind": f.kind,
        "method": f.method,
        "margin_m": round(f.margin_m, 3),
        "alt_min_m": f.alt_min_m,
        "alt_max_m": f.alt_max_m,
        "vertices": vertices,
        "area_m2": round(area_m2, 1),
        "sources": list(f.sources),
    }
    if f.alpha_m is not None:
        props["alpha_m"] = round(f.alpha_m, 3) if f.alpha_m != float("inf") else None
    if f.circle is not None:
        lon, lat, r = f.circle_wgs84
        props["center"] = [round(lon, 9), round(lat, 9)]
        props["radius_m"] = round(r, 3)
    if f.repaired:
        props["repaired"] = True
    if f.properties:
        props["zone"] = f.properties
    return props


def fences_geojson(fences, meta: dict | None = None) -> dict:
    """Built fences as a GeoJSON FeatureCollection (coordinates rounded to 1e-8 degrees).

    Parameters
    ----------
    fences : list of Fence
    meta : dict, optional
        What the build was made of, stored under ``"alphafence"``.

    Returns
    -------
    dict
        Ready for :func:`dumps`.
    """
    doc = {"type": "FeatureCollection", "generator": f"alphafence {__version__}"}
    if meta:
        doc["alphafence"] = meta
    doc["features"] = fence_features(fences)
    return doc


def fence_features(fences) -> list:
    """The GeoJSON Features of built fences: :func:`fence_properties` and the WGS84 geometry,
    coordinates rounded to ``DECIMALS`` places exactly as ``round(v, DECIMALS)`` rounds them.

    The fences' coordinates are taken together: each frame's in one transformation (a site's
    fences share its frame), all of them rounded in one vectorised step.

    Parameters
    ----------
    fences : list of Fence

    Returns
    -------
    list of dict
        One ``{"type": "Feature", "properties": ..., "geometry": ...}`` per fence, in order;
        a ``fence_text.FenceFeatures``, which keeps the coordinates for the writers.
    """
    with paused_gc():  # millions of small lists and floats
        return _features(list(fences))


def _features(fences):
    if not fences:
        return []
    local = np.array([f.local for f in fences], dtype=object)
    kinds = shapely.get_type_id(local)
    structure = ring_structure(local, kinds)
    if structure is None or any(getattr(f, "wgs84", None) is not None for f in fences):
        # anything but flat (multi)polygons of non-empty parts, or fences split at the
        # antimeridian: GEOS writes
        return [_feature(f, json.loads(shapely.to_geojson(f.geometry))) for f in fences]
    size, ring_part, owner = structure
    fence_ends = np.cumsum(shapely.get_num_coordinates(local)).tolist()
    xy = _round_array(wgs84_coordinates(fences, shapely.get_coordinates(local), fence_ends))
    flat = xy.tolist()
    ends = np.cumsum(size).tolist()
    ring_lists = [flat[a:b] for a, b in zip([0, *ends[:-1]], ends)]
    # the rings of each part, the parts of each fence: runs of the lists, in order
    part_rings = _runs(ring_lists, ring_part, len(owner))
    fence_parts = _runs(part_rings, owner, len(fences))
    vertices, areas = fence_numbers(fences)
    out = [
        {
            "type": "Feature",
            "properties": _properties(f, n, area),
            "geometry": (
                {"type": "Polygon", "coordinates": polys[0]}
                if kind == 3
                else {"type": "MultiPolygon", "coordinates": polys}
            ),
        }
        for f, kind, polys, n, area in zip(fences, kinds.tolist(), fence_parts, vertices, areas)
    ]
    return FenceFeatures(out, local, xy, size, ring_part, owner)


def _runs(items, group, groups):
    """``items`` cut into ``groups`` lists: the runs of equal (non-decreasing) ``group``."""
    if len(items) == groups and np.array_equal(group, np.arange(groups)):
        return [[x] for x in items]
    ends = np.cumsum(np.bincount(group, minlength=groups)).tolist()
    return [items[a:b] for a, b in zip([0, *ends[:-1]], ends)]


def _feature(f, geometry):
    geometry["coordinates"] = _round(geometry["coordinates"])
    return {"type": "Feature", "properties": fence_properties(f), "geometry": geometry}


def _round_array(a):
    """``round(v, DECIMALS)`` of every element of float array ``a``, vectorised: the scaled
    value's nearest integer is Python's unless the scaling's own rounding could have moved
    it across a half, and those few are rounded by Python."""
    scale = 10.0**DECIMALS
    y = a * scale
    out = np.rint(y) / scale
    with np.errstate(invalid="ignore"):
        doubt = ~(np.abs(y - np.floor(y) - 0.5) > 4.0 * np.spacing(np.abs(y)))
    for k in zip(*np.nonzero(doubt)):
        out[k] = round(float(a[k]), DECIMALS)
    return out


def _round(c):
    if isinstance(c, list) and c and isinstance(c[0], (int, float)):
        return [round(v, DECIMALS) for v in c]
    return [_round(x) for x in c]


def dumps(doc) -> str:
    """The document as compact JSON text (UTF-8 kept as is), one line and a newline.

    Examples
    --------
    >>> dumps({"type": "FeatureCollection", "features": []})
    '{"type":"FeatureCollection","features":[]}\\n'
    """
    return json.dumps(doc, separators=(",", ":"), ensure_ascii=False) + "\n"
