"""What ED-269 and ED-318 zones share: altitude limits and their units, circles built in
metres, polygon shapes, reasons and the pseudo-tags the rules match on. Each raises a
one-line InputError naming the file and the zone (``label``)."""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence.errors import InputError
from alphafence.geo.coords import valid_lonlat
from alphafence.geo.frame import LocalFrame

UNITS = {"M": 1.0, "FT": 0.3048}
_CIRCLE_SEGMENTS = 64
_SHAPE_ERRORS = (ValueError, TypeError, IndexError, KeyError, AttributeError, OverflowError)


def circle_polygon(lon, lat, radius_m):
    """A WGS84 polygon that contains the circle (circumscribed, so never cuts into it), its
    inscribed circle the circle itself: a keep-in zone's circle is taken as it is.

    Parameters
    ----------
    lon, lat : float
        The centre, degrees.
    radius_m : float
        The radius, metres (the polygon is built in a local metric frame).

    Returns
    -------
    shapely.Polygon
        64 vertices.
    """
    frame = LocalFrame(lon, lat)
    r_out = radius_m / math.cos(math.pi / _CIRCLE_SEGMENTS)
    ang = (
        np.linspace(0.0, 2.0 * math.pi, _CIRCLE_SEGMENTS, endpoint=False)
        + math.pi / _CIRCLE_SEGMENTS
    )
    lons, lats = frame.to_wgs84(r_out * np.cos(ang), r_out * np.sin(ang))
    return shapely.Polygon(np.column_stack([lons, lats]))


def number(value):
    """A finite float from a number or a numeric string (``"0"``), else None."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        return None
    try:
        value = float(value.strip() if isinstance(value, str) else value)
    except (ValueError, OverflowError):  # "ten"; an integer beyond any float
        return None
    return value if math.isfinite(value) else None


def limit(path, label, geom, key, units):
    """``geom[key]`` (a number or a numeric string) in metres, or None when it is absent."""
    value = geom.get(key)
    if value is None:
        return None
    read = number(value)
    if read is None:
        raise InputError(path, f"{key} must be a number, not {value!r}", label)
    return read * units


def unit(path, label, value, key):
    """Metres per unit of ``value`` (``M`` or ``FT``, either case)."""
    name = value.upper() if isinstance(value, str) else None  # a list is no unit (nor a key)
    if name not in UNITS:
        raise InputError(path, f"{key} must be M or FT, not {value!r}", label)
    return UNITS[name]


def band(path, label, lower, upper, keys=("lowerLimit", "upperLimit")):
    """Refuse an altitude band whose upper limit is not above its lower one."""
    if lower is not None and upper is not None and upper <= lower:
        raise InputError(path, f"{keys[1]} {upper} m is not above {keys[0]} {lower} m", label)


def circle(path, label, center, radius, units):
    """``(polygon, {"circle": [lon, lat, radius_m]})`` of a circle: ``center`` [lon, lat],
    ``radius`` in ``units``; the polygon contains the circle (:func:`circle_polygon`)."""
    if (
        not isinstance(center, list)
        or len(center) != 2
        or not all(isinstance(c, (int, float)) and number(c) is not None for c in center)
        or not valid_lonlat(*center)
    ):
        raise InputError(path, f"Circle center must be [lon, lat] in range, not {center!r}", label)
    r = number(radius)
    if r is None or not r > 0:
        raise InputError(path, f"Circle radius must be a positive number, not {radius!r}", label)
    radius_m = r * units
    return circle_polygon(center[0], center[1], radius_m), {
        "circle": [center[0], center[1], radius_m]
    }


def shape(path, label, gtype, coordinates):
    """A Polygon or MultiPolygon from GeoJSON-style ``coordinates`` (lon, lat)."""
    try:
        return shapely.geometry.shape({"type": gtype, "coordinates": coordinates})
    except (*_SHAPE_ERRORS, ShapelyError) as exc:
        raise InputError(path, f"malformed {gtype} ({exc})", label) from None


def projection(path, label, proj, units=1.0):
    """``(geometry, extra properties)`` of an ED-269 ``horizontalProjection``."""
    if not isinstance(proj, dict):
        raise InputError(path, "horizontalProjection must be an object", label)
    ptype = proj.get("type")
    if ptype == "Circle":  # uomDimensions applies to the radius too
        return circle(path, label, proj.get("center"), proj.get("radius"), units)
    if ptype in ("Polygon", "MultiPolygon"):
        return shape(path, label, ptype, proj.get("coordinates")), {}
    raise InputError(path, f"unknown horizontalProjection type {ptype!r}", label)


def reasons(value):
    """A zone's reasons as a list (one given alone, or none)."""
    return [] if not value else value if isinstance(value, list) else [value]


def tags(restriction, why, name):
    """The pseudo-tags the rules match a zone on: ``ed269:restriction``, ``ed269:reason``
    (its reasons, ``;``-joined) and ``name``.

    Examples
    --------
    >>> tags("PROHIBITED", ["AIR_TRAFFIC", "SENSITIVE"], "Luqa")
    {'ed269:restriction': 'PROHIBITED', 'ed269:reason': 'AIR_TRAFFIC;SENSITIVE', 'name': 'Luqa'}
    """
    out = {"ed269:restriction": restriction}
    if why:
        out["ed269:reason"] = ";".join(str(r) for r in why)
    if name:
        out["name"] = str(name)
    return out


def volume(geom, tags_, ident, j, count, band_m, zone, references, extra):
    """One volume of a zone as the readers yield it: ``(geometry, tags, source, lower, upper,
    properties)``, its source the zone's identifier (``#j`` after it when the zone has
    ``count`` > 1 geometries), its properties the zone's ``restriction``, ``reason`` and
    ``applicability`` (``zone``, a dict) and the band's ``references`` (lower, upper)."""
    props = {
        **zone,
        "lower_reference": references[0],
        "upper_reference": references[1],
        **extra,
    }
    source = str(ident) if count == 1 else f"{ident}#{j}"
    return geom, dict(tags_), source, band_m[0], band_m[1], props
