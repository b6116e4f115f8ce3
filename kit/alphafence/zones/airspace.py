"""Airspace volumes (KML/KMZ placemarks, OpenAir airspaces, ArduPilot and QGC fences) made into
restricted features for a build or into fences read as they are.

A reader yields volumes ``(geometry, tags, source, lower_m, upper_m, properties)``: WGS84
lon/lat shapely geometry, the pseudo-tags the rules match on (``airspace:format``,
``airspace:class``, ``name``...), the altitude band in metres (None: unbounded) and properties
kept on the fence (``lower_reference``, ``upper_reference``, ``circle``). This module turns
them into :class:`~alphafence.zones.features.Feature` lists (rules decide the kind); the
fence files read them as fences (:mod:`alphafence.fencefiles.volume_fences`).
Circles are drawn circumscribed (outward): never cutting into the circle.

A reader whose volumes can be read two ways (KML's long edges, straight in lon/lat or along
geodesics: :mod:`alphafence.zones.kml_geodesic`) passes *readings* as well: for such a
volume the area a keep-out or warning zone holds and the one a keep-in zone holds, taken
once the volume's kind is known.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.geo.frame import LocalFrame
from alphafence.zones.features import (
    Feature,
    check_coordinates,
    flag_invalid,
    geomtype_of,
)

SAG_M = 1.0  # a circumscribed arc lies at most this far outside the true arc (plus PAD_M)
PAD_M = 0.5  # every arc vertex this much further out: straight edges in degrees stay outside
MIN_STEP_DEG, MAX_STEP_DEG = 0.5, 10.0


def arc_step(radius_m) -> float:
    """The angular step (degrees) of a circumscribed arc of ``radius_m`` whose edges lie at
    most :data:`SAG_M` outside the true arc, between 0.5 and 10 degrees.

    Examples
    --------
    >>> round(arc_step(9260.0), 2)  # 5 NM: a 1.7-degree step
    1.68
    """
    r = max(float(radius_m), 1e-9)
    step = math.degrees(2.0 * math.acos(r / (r + SAG_M)))
    return min(max(step, MIN_STEP_DEG), MAX_STEP_DEG)


def circumscribed_points(radius_m, bearings_deg, step_deg):
    """Vertices of edges tangent to a circle (``radius_m`` + :data:`PAD_M`), one between each
    two neighbouring ``bearings_deg`` ``step_deg`` apart: the polyline never cuts in.

    Returns
    -------
    numpy.ndarray, shape (n, 2)
        x (east), y (north) in metres about the circle's centre.
    """
    half = math.radians(step_deg) / 2.0
    r_out = (radius_m + PAD_M) / math.cos(half)
    b = np.radians(np.asarray(bearings_deg, float))
    return np.column_stack([r_out * np.sin(b), r_out * np.cos(b)])


def circle_polygon(lon, lat, radius_m):
    """A WGS84 polygon around the geodesic circle of ``radius_m`` about (lon, lat), every edge
    outside it (tangent to a circle :data:`PAD_M` larger).

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> poly = circle_polygon(-1.5, 52.2, 1852.0)
    >>> local = LocalFrame(-1.5, 52.2).geom_to_local(poly)
    >>> bool(local.covers(shapely.Point(0, 0).buffer(1852.0, quad_segs=256)))
    True
    """
    step = arc_step(radius_m)
    n = max(3, math.ceil(360.0 / step))
    step = 360.0 / n
    xy = circumscribed_points(radius_m, (np.arange(n) + 0.5) * step, step)
    lons, lats = LocalFrame(lon, lat).to_wgs84(xy[:, 0], xy[:, 1])
    return shapely.Polygon(np.column_stack([lons, lats]))


def held_reading(path, geom, readings, k, kind, label):
    """The area volume ``k`` holds as a zone of ``kind``: its keep-in or keep-out reading
    when it has ``readings``, else ``geom``."""
    if readings is None or readings[k] is None:
        return geom
    held = readings[k][1 if kind == "keep_in" else 0]
    if held.is_empty:
        msg = "a keep-in zone whose edges read straight in lon/lat and along great circles"
        raise InputError(path, f"{msg} share no area", label)
    return held


def features_from_volumes(path, volumes, rules, repaired, skipped, what, readings=None):
    """Restricted features of the volumes a reader yielded, each matched against ``rules``
    (a volume's band wins over its rule's; missing limits come from the rule).

    Parameters
    ----------
    path : str or Path
    volumes : list of tuple
        ``(geometry, tags, source, lower_m, upper_m, properties)``.
    rules : Rules
    repaired : list
        Sources of invalid polygons are appended (repaired later, in metres).
    skipped : collections.Counter
        Volumes no rule matches are counted, by ``what`` and class.
    what : str
        The format, for those counts (``"OpenAir airspace"``).
    readings : list, optional
        One per volume: None, or the ``(keep_out, keep_in)`` areas it holds as a zone of
        that kind (a warning as a keep-out); its own geometry is checked and flagged.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        A coordinate out of range or an empty geometry, naming the volume; a keep-in zone
        whose readings share no area.
    """
    if not volumes:
        return []
    geoms = np.array([v[0] for v in volumes], dtype=object)
    check_coordinates(path, geoms, lambda k: f"{what} {volumes[k][2]}")
    geoms = flag_invalid(geoms, [v[2] for v in volumes], repaired)
    out = []
    for k, (g, (_, tags, source, lower, upper, props)) in enumerate(zip(geoms, volumes)):
        rule = rules.match(tags.get, geomtype_of(g) or "area")
        if rule is None:
            skipped[f"{what} of class {tags.get('airspace:class', '?')} (no rule)"] += 1
            continue
        g = held_reading(path, g, readings, k, rule.kind, f"{what} {source}")
        alt_min = lower if lower is not None else rule.alt_min_m
        alt_max = upper if upper is not None else rule.alt_max_m
        out.append(Feature(g, tags, source, str(path), rule, alt_min, alt_max, props))
    return out


def polygonal(geom):
    """The polygonal part of a (repaired) geometry, or None when it has none.

    Examples
    --------
    >>> polygonal(shapely.GeometryCollection([shapely.box(0, 0, 1, 1), shapely.Point(5, 5)]))
    <POLYGON ((1 0, 1 1, 0 1, 0 0, 1 0))>
    """
    if geom.geom_type in ("Polygon", "MultiPolygon"):
        return geom
    parts = [p for p in shapely.get_parts(geom) if p.geom_type in ("Polygon", "MultiPolygon")]
    if not parts:
        return None
    return shapely.union_all(parts)
