"""KML placemarks made volumes: bands from altitudes, footprints from floors, ceilings and
vertical walls, and a zone drawn as several placemarks put back together.

A placemark's geometries (as :mod:`alphafence.zones.kml` reads them) make volumes:

* an extruded geometry, a point or a line is a volume of its own; an extruded one reaches the
  ground;
* its other polygons are one volume: their footprints united, the band from the lowest to the
  highest altitude. A *vertical wall* (a polygon whose horizontal projection has no area and
  whose altitudes vary) adds only its altitudes; walls without a floor or ceiling stand on the
  outline their horizontal lines close.

Some airspace exports draw each volume as separate placemarks in one Folder: a floor polygon,
a ceiling polygon and one placemark per wall, all named after the zone, or named after it with
what each is (``NAME lower``, ``NAME upper``, ``NAME side 3``, as national eAIP exports do). A
placemark holding only walls has no area of its own: the placemarks of its Folder with its name
(less such a word) that hold only (not extruded) polygons are read as one zone, named ``NAME``,
in the place of the first of them. Its floor and ceiling give its footprint and band; its walls
give the outline only where it has neither, so a wall of zero width in a whole volume is nothing.

Each function that makes areas takes an optional *reading*: the 2-D polygon a placemark's
polygon is read as (e.g. with its edges along geodesics,
:func:`alphafence.zones.kml_geodesic.geodesic_reading`), used for the area while what the
polygon is (a floor, a wall) is judged on it as written.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence.errors import InputError
from alphafence.zones.airspace import circle_polygon

_REFERENCES = {"absolute": "AMSL", "relativeToGround": "AGL"}
_WALL = 1e-6  # a polygon whose area is below this times its perimeter squared is a wall
# a volume's part named after it: "NAME upper", "NAME lower", "NAME side 12", "NAME wall 3"
_PART = re.compile(
    r"^(?P<stem>.*?\S)[\s_-]+(?:upper|lower|top|bottom|floor|ceiling|side|wall)(?:[\s_-]*\d+)?$",
    re.IGNORECASE,
)


def zone_name(name):
    """The zone a placemark's name says it is part of: the name less a closing word that says
    which part (``upper``, ``lower``, ``side N``, ...).

    Examples
    --------
    >>> [zone_name(n) for n in ("EY D 99 upper", "EY D 99 side 12", "EY D 99", None)]
    ['EY D 99', 'EY D 99', 'EY D 99', None]
    """
    if not name:
        return name
    found = _PART.match(str(name).strip())
    return found.group("stem") if found else name


@dataclass(eq=False)
class Placemark:
    """A KML Placemark as read: its geometries and what names it.

    Attributes
    ----------
    index : int
        Its place among the document's placemarks.
    label : str
        How messages name it (``"placemark 3 (EG D999)"``).
    name : str or None
    folder : object
        Its innermost Folder element (None outside any): a zone's placemarks share it.
    ident : str
        Its ``id``, else ``placemark/<index>``.
    tags : dict
        Pseudo-tags for the rules.
    prims : list of tuple
        ``(kind, 2-D shapely geometry, altitudes, altitudeMode, extrude)`` of each geometry,
        ``kind`` ``"area"``, ``"line"`` or ``"point"``.
    radius : float or None
        ExtendedData ``radius`` (metres): its points are circles.
    """

    index: int
    label: str
    name: object
    folder: object
    ident: str
    tags: dict
    prims: list
    radius: object = None


def band(prims, extruded=False):
    """The altitude band of geometries that share one altitudeMode.

    Parameters
    ----------
    prims : list of tuple
        As :attr:`Placemark.prims`.
    extruded : bool
        The geometry reaches down to the ground: the band is 0 up to its highest point.

    Returns
    -------
    tuple
        ``(lower, upper, reference)``: metres and ``"AMSL"`` or ``"AGL"``; ``(None, None,
        None)`` when the modes differ, one is ``clampToGround``, an altitude is missing, or
        the geometries are flat (one altitude: a keep-out at every height).
    """
    modes = {p[3] for p in prims}
    zs = np.concatenate([p[2] for p in prims]) if prims else np.array([])
    if len(modes) != 1 or (ref := _REFERENCES.get(modes.pop())) is None:
        return None, None, None
    if zs.size == 0 or np.isnan(zs).any():
        return None, None, None
    low, high = float(zs.min()), float(zs.max())
    if extruded:
        return (0.0, high, ref) if high > 0 else (None, None, None)
    return (low, high, ref) if high > low else (None, None, None)


def _no_area(geom):
    length = geom.length
    return length == 0 or geom.area <= _WALL * length * length


def is_wall(prim) -> bool:
    """Whether a geometry is a vertical wall: a polygon, not extruded, whose horizontal
    projection has no area and whose altitudes vary.

    Examples
    --------
    >>> import numpy as np, shapely
    >>> wall = shapely.Polygon([(0, 0), (1, 0), (1, 0), (0, 0)])
    >>> is_wall(("area", wall, np.array([10.0, 10.0, 90.0, 90.0]), "absolute", False))
    True
    >>> is_wall(("area", wall, np.array([10.0, 10.0, 10.0, 10.0]), "absolute", False))
    False
    """
    kind, geom, zs, _, extrude = prim
    if kind != "area" or extrude or not _no_area(geom):
        return False
    zs = zs[np.isfinite(zs)]
    return zs.size > 0 and float(zs.max()) > float(zs.min())


def _faceless(prim) -> bool:
    """A polygon, not extruded, without area of its own: a vertical wall, or a floor or
    ceiling drawn edge-on (a ring of two points and back)."""
    return prim[0] == "area" and not prim[4] and _no_area(prim[1])


def _as_written(geom):
    return geom


def footprint(path, label, prims, reading=None):
    """The area under polygons of one volume: floors and ceilings united (an identical floor
    and ceiling are one), or, with only polygons without area (vertical walls), the outline
    their horizontal lines close.

    Parameters
    ----------
    path : str or Path
    label : str
        The placemark messages name.
    prims : list of tuple
        Polygons, as :attr:`Placemark.prims`.
    reading : callable, optional
        The polygon each is read as (by default as written).

    Returns
    -------
    shapely geometry

    Raises
    ------
    InputError
        A polygon without area that is no wall, or walls alone that close no ring.
    """
    read = reading or _as_written
    floors = [read(p[1]) for p in prims if not _no_area(p[1])]
    unique = list({shapely.normalize(f).wkb: f for f in floors}.values())
    if len(unique) == 1:
        return unique[0]
    if unique:
        try:
            geom = shapely.union_all(unique)
        except ShapelyError:
            geom = shapely.union_all(shapely.make_valid(np.array(unique, dtype=object)))
    else:  # the horizontal lines of polygons without area, noded, as rings
        try:
            lines = shapely.union_all([shapely.boundary(read(p[1])) for p in prims])
            lines = [g for g in shapely.get_parts(lines) if g.geom_type == "LineString"]
            geom = shapely.union_all(shapely.get_parts(shapely.polygonize(lines)))
        except ShapelyError:
            geom = shapely.GeometryCollection()
        if geom.is_empty and all(is_wall(p) for p in prims):
            msg = "vertical walls whose horizontal lines close no ring, and no floor or ceiling"
            raise InputError(path, msg, label)
    if geom.is_empty:
        raise InputError(path, "a polygon without area", label)
    return geom


def _placemark_volumes(path, pm, reading):
    parts = []  # (geometry, lower, upper, lower reference, upper reference, extra properties)
    for p in pm.prims:
        if p[4] or p[0] != "area":  # extruded, points and lines: each its own volume
            lower, upper, ref = band([p], p[4])
            geom, extra = (reading(p[1]) if p[0] == "area" else p[1]), {}
            if p[0] == "point" and pm.radius is not None:
                lon, lat = p[1].x, p[1].y
                geom = circle_polygon(lon, lat, pm.radius)
                extra = {"circle": [lon, lat, pm.radius]}
            parts.append((geom, lower, upper, ref and ("AGL" if p[4] else ref), ref, extra))
    rest = [p for p in pm.prims if not p[4] and p[0] == "area"]
    if rest:
        lower, upper, ref = band(rest)
        parts.append((footprint(path, pm.label, rest, reading), lower, upper, ref, ref, {}))
    volumes = []
    for k, (geom, lower, upper, lref, uref, extra) in enumerate(parts):
        props = {"lower_reference": lref, "upper_reference": uref, **extra} if uref else extra
        source = pm.ident if len(parts) == 1 else f"{pm.ident}#{k}"
        volumes.append((geom, dict(pm.tags), source, lower, upper, props))
    return volumes


def _zone_volume(path, members, reading):
    """One volume of a zone drawn as several placemarks (floor, ceiling, walls)."""
    prims = [p for pm in members for p in pm.prims]
    walls = next(pm for pm in members if pm.prims and all(_faceless(p) for p in pm.prims))
    lower, upper, ref = band(prims)
    geom = footprint(path, walls.label, prims, reading)
    tags = {}
    for pm in reversed(members):  # the first placemark's values win
        tags.update(pm.tags)
    if members[0].name:
        tags["name"] = zone_name(members[0].name)
    props = {"lower_reference": ref, "upper_reference": ref} if ref else {}
    return geom, tags, members[0].ident, lower, upper, props


def volumes(path, marks, reading=None, faults=None):
    """The volumes of a document's placemarks, in document order.

    Parameters
    ----------
    path : str or Path
    marks : list of Placemark
    reading : callable, optional
        The 2-D polygon each polygon is read as (by default as written): with or without it
        the same volumes come back, in the same order.
    faults : list, optional
        When given, a placemark whose polygons have no area is left out and its InputError
        appended here, instead of raised.

    Returns
    -------
    list of tuple
        ``(geometry, tags, source, lower_m, upper_m, properties)``, as
        :func:`alphafence.zones.airspace.features_from_volumes` takes them.

    Raises
    ------
    InputError
        One line naming the placemark whose polygons have no area.
    """

    def key(pm):
        return pm.folder, zone_name(pm.name)

    def areas(pm):
        return bool(pm.prims) and all(p[0] == "area" and not p[4] for p in pm.prims)

    reading = reading or _as_written
    zones = {key(pm): [] for pm in marks if pm.prims and all(_faceless(p) for p in pm.prims)}
    for pm in marks:
        if key(pm) in zones and areas(pm):
            zones[key(pm)].append(pm)
    out = []
    for pm in marks:
        members = zones.get(key(pm)) if areas(pm) else None
        try:
            if not members:
                out.extend(_placemark_volumes(path, pm, reading))
            elif members[0] is pm:
                out.append(_zone_volume(path, members, reading))
        except InputError as exc:
            if faults is None:
                raise
            faults.append(exc)
    return out
