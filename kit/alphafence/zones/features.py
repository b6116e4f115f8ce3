"""Restricted features as read from a geofence database (WGS84, lon/lat)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import shapely

from alphafence.errors import InputError, InputErrors
from alphafence.geo.coords import check_lonlat_array

GEOMTYPES = {
    "Point": "point",
    "MultiPoint": "point",
    "LineString": "line",
    "MultiLineString": "line",
    "LinearRing": "line",
    "Polygon": "area",
    "MultiPolygon": "area",
}


@dataclass
class Feature:
    """A restricted feature as read from a geofence database.

    Attributes
    ----------
    geometry : shapely geometry
        WGS84 lon, lat; possibly invalid (repaired later, in a metric frame).
    tags : dict
        OSM tags, or the pseudo-tags of an ED-269 zone.
    source : str
        ``"way/123"``, ``"relation/9"``, ``"node/5"``, ``"feature/3"`` or an ED-269 identifier.
    origin : str
        The file it came from.
    rule : Rule
        The rule that matched it.
    alt_min_m, alt_max_m : float, optional
        Its altitude band (the zone's, else the rule's).
    properties : dict
        E.g. an ED-269 zone's restriction and applicability.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.zones.rules import load_rules
    >>> tags = {"amenity": "hospital", "name": "St. Luke"}
    >>> rule = load_rules().match(tags.get, "area")
    >>> ward = Feature(shapely.box(14.5, 35.9, 14.501, 35.901), tags, "way/1", "demo", rule)
    >>> ward.name, ward.geomtype, ward.category, ward.kind
    ('St. Luke', 'area', 'hospital', 'keep_out')
    """

    geometry: object  # shapely geometry, WGS84 lon/lat
    tags: dict
    source: str  # "way/123", "relation/9", "node/5", "feature/3", ED-269 identifier
    origin: str  # the file it came from
    rule: object  # alphafence.zones.rules.Rule
    alt_min_m: float | None = None
    alt_max_m: float | None = None
    properties: dict = field(default_factory=dict)  # e.g. ED-269 restriction, applicability

    @property
    def name(self) -> str | None:
        """Its ``name`` tag, if any."""
        return self.tags.get("name")

    @property
    def geomtype(self) -> str:
        """``"point"``, ``"line"`` or ``"area"``."""
        return GEOMTYPES.get(self.geometry.geom_type, "area")

    @property
    def category(self) -> str:
        """Its rule's category."""
        return self.rule.category

    @property
    def kind(self) -> str:
        """Its rule's kind: ``"keep_out"``, ``"warning"`` or ``"keep_in"``."""
        return self.rule.kind


@dataclass
class Database:
    """What ``read_database`` read.

    Attributes
    ----------
    features : list of Feature
        The restricted features (inside ``bbox`` when one was given).
    files : list of str
    repaired : list of str
        Sources of invalid polygons (they are repaired in each site's frame).
    skipped : collections.Counter
        Reason -> how many features were left out for it.
    bbox : tuple, optional
        ``(minlon, minlat, maxlon, maxlat)`` the features were selected by.
    notes : list of str
        What was read other than as written, one line each (an OpenAir limit without a
        numeric meaning, widened).
    invalid : list of dict
        Zones left out because they could not be read as areas (asked for with
        ``skip_invalid``): ``file``, ``airspace``, ``line``, ``problem``.
    """

    features: list
    files: list
    repaired: list = field(default_factory=list)  # sources of invalid polygons that were repaired
    skipped: Counter = field(default_factory=Counter)  # reason -> count
    bbox: tuple | None = None
    notes: list = field(default_factory=list)
    invalid: list = field(default_factory=list)


def geomtype_of(geom) -> str | None:
    """``"point"``, ``"line"`` or ``"area"`` for a geometry's type, or None for others.

    Examples
    --------
    >>> import shapely
    >>> geomtype_of(shapely.Point(0, 0)), geomtype_of(shapely.GeometryCollection())
    ('point', None)
    """
    return GEOMTYPES.get(geom.geom_type)


def check_coordinates(path, geoms, label):
    """Raise a one-line InputError for the first geometry with a coordinate out of range, or
    empty.

    ``label(i)`` names feature i for the message.
    """
    faults = coordinate_faults(path, geoms, label)
    if faults:
        raise faults[min(faults)]


def coordinate_faults(path, geoms, label) -> dict:
    """``{i: InputError}`` for each geometry i with a coordinate out of range (its first
    one named), or empty (vectorised).

    ``label(i)`` names feature i for the message.
    """
    geoms = np.asarray(geoms, dtype=object)
    if geoms.size == 0:
        return {}
    coords, index = shapely.get_coordinates(geoms, return_index=True)
    bad = ~(
        np.isfinite(coords).all(axis=1)
        & (np.abs(coords[:, 0]) <= 180.0)
        & (np.abs(coords[:, 1]) <= 90.0)
    )
    faults = {}
    for row in np.flatnonzero(bad):
        i = int(index[row])
        if i not in faults:
            lon, lat = coords[row]
            faults[i] = InputError(
                path, f"coordinate ({lon}, {lat}) out of range (lon -180..180, lat -90..90)",
                label(i),
            )  # fmt: skip
    for i in np.flatnonzero(shapely.is_empty(geoms)):
        faults.setdefault(int(i), InputError(path, "empty geometry", label(int(i))))
    return faults


def flag_invalid(geoms, sources, repaired):
    """Record invalid (e.g. self-intersecting) polygons. They are repaired later, in the
    site's metric frame: repairing in degrees would misread shapes across the antimeridian."""
    geoms = np.asarray(geoms, dtype=object)
    if geoms.size:
        for i in np.flatnonzero(~shapely.is_valid(geoms)):
            repaired.append(sources[i])
    return geoms


def invalid_entries(path, faults, invalid) -> None:
    """Describe each fault (an InputError) of a file left out by ``--skip-invalid`` in
    ``invalid``: ``file``, ``airspace`` (the feature or placemark the fault names), ``line``
    (None) and ``problem``, as the OpenAir reader's faults are."""
    for exc in faults:
        invalid.append({"file": str(path), "airspace": exc.feature, "line": None,
                        "problem": exc.message})  # fmt: skip


def settle_faults(path, faults, invalid) -> None:
    """The end of reading a file: each fault found (InputErrors, in order) is left out and
    described in ``invalid`` (``--skip-invalid``), or, when ``invalid`` is None, raised: one
    as its own line, several at once (:class:`~alphafence.errors.InputErrors`)."""
    if not faults:
        return
    if invalid is None:
        for exc in faults:
            exc.skippable = True  # a zone --skip-invalid leaves out (the command says so)
        raise faults[0] if len(faults) == 1 else InputErrors(path, faults)
    invalid_entries(path, faults, invalid)


def make_valid_polygonal(geoms):
    """Valid geometries (vectorised). Repair never shrinks: it may leave a collection of
    polygons plus the lines a spike or a collapsed ring draws
    (:func:`alphafence.geo.lonlat.repair_keeping_all`); all of it stays restricted."""
    from alphafence.geo.lonlat import repair_keeping_all

    return repair_keeping_all(np.asarray(geoms, dtype=object))


def select_bbox(features, bbox):
    """Features whose extent meets (minlon, minlat, maxlon, maxlat)."""
    if bbox is None or not features:
        return features
    box = shapely.box(*bbox)
    geoms = np.array([f.geometry for f in features], dtype=object)
    keep = shapely.intersects(shapely.envelope(geoms), box)
    return [f for f, k in zip(features, keep) if k]


def parse_bbox(text: str, name: str = "bounding box"):
    """``"minlon,minlat,maxlon,maxlat"`` -> a (minlon, minlat, maxlon, maxlat) tuple of floats.

    Parameters
    ----------
    text : str
        Four comma-separated numbers, lon/lat in degrees.
    name : str, optional
        What the text is, named in the error.

    Raises
    ------
    InputError
        Not four numbers, coordinates out of range, or a min not below its max.

    Examples
    --------
    >>> parse_bbox("-77.5,38.7,-77.0,39.0")
    (-77.5, 38.7, -77.0, 39.0)
    """
    try:
        parts = [float(p) for p in text.split(",")]
    except ValueError:
        parts = []
    if len(parts) != 4:
        raise InputError(name, f"expected minlon,minlat,maxlon,maxlat, got {text!r}")
    minlon, minlat, maxlon, maxlat = parts
    if check_lonlat_array([[minlon, minlat], [maxlon, maxlat]]) is not None:
        raise InputError(name, f"coordinates out of range in {text!r}")
    if minlon >= maxlon or minlat >= maxlat:
        raise InputError(name, f"min must be below max in {text!r}")
    return (minlon, minlat, maxlon, maxlat)


_DEPTHS = {"Point": 1, "MultiPoint": 2, "LineString": 2, "MultiLineString": 3, "Polygon": 3,
           "MultiPolygon": 4}  # fmt: skip


def geometry_problem(gj, inside: bool = False) -> str | None:
    """What is wrong with the shape of a GeoJSON geometry object, before GEOS reads it, or
    None: its type, its coordinates nested exactly as deep as the type says (a hostile answer
    can nest them hundreds deep), and each position two to four finite numbers (JSON's
    ``NaN`` and ``1e999`` are not). Iterative: no input makes it recurse more than once.

    Examples
    --------
    >>> geometry_problem({"type": "Polygon", "coordinates": [[[14.5, 35.9], [14.6, 35.9],
    ...                                                        [14.5, 36.0], [14.5, 35.9]]]})
    >>> geometry_problem({"type": "Polygon", "coordinates": [[[[14.5, 35.9]]]]})
    'Polygon coordinates nested deeper than a Polygon nests them'
    >>> geometry_problem({"type": "Point", "coordinates": [14.5, float("nan")]})
    'Point coordinate is not a finite number (nan)'
    """
    if not isinstance(gj, dict) or not isinstance(gj.get("type"), str):
        return "geometry must be an object with a type"
    kind = gj["type"]
    if kind == "GeometryCollection":
        parts = gj.get("geometries")
        if inside or not isinstance(parts, list):
            return "GeometryCollection without a 'geometries' list, or within another"
        return next((p for p in (geometry_problem(g, True) for g in parts) if p), None)
    depth = _DEPTHS.get(kind)
    if depth is None:
        return f"unknown geometry type {kind[:40]!r}"
    level = [gj.get("coordinates")]
    for _ in range(depth - 1):
        if not all(isinstance(item, list) for item in level):
            return f"{kind} coordinates not nested as a {kind} nests them"
        level = [x for item in level for x in item]
    return _position_problem(kind, level)


def _position_problem(kind, positions) -> str | None:
    """A geometry's positions: each a list of two to four finite numbers."""
    if not all(isinstance(p, list) for p in positions):
        return f"{kind} coordinates not nested as a {kind} nests them"
    values = [v for p in positions for v in p]
    if any(isinstance(v, list) for v in values):
        return f"{kind} coordinates nested deeper than a {kind} nests them"
    if not all(2 <= len(p) <= 4 for p in positions):
        return f"{kind} position without two to four numbers"
    if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in values):
        return f"{kind} coordinate is not a number"
    numbers = np.asarray(values, dtype=float)
    if not np.isfinite(numbers).all():
        return f"{kind} coordinate is not a finite number ({numbers[~np.isfinite(numbers)][0]})"
    return None
