"""The outlines of OpenAir airspaces: positions (``DP``, ``V X=``, ``DB``), arcs (``DA``,
``DB``) and circles (``DC``) made into a polygon drawn outward, never cutting into the
airspace: a convex arc by tangents outside it, a concave one by chords inside it.
"""

from __future__ import annotations

import math
import re

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.geo.frame import LocalFrame
from alphafence.zones.airspace import PAD_M, arc_step, circle_polygon, circumscribed_points

_COORD = re.compile(r"(\d+(?:\.\d+)?)(?::(\d+(?:\.\d+)?))?(?::(\d+(?:\.\d+)?))?\s*([NSEWnsew])")


def parse_coordinates(path, where, text, count):
    """``count`` positions ``(lon, lat)`` from OpenAir text: latitude (N/S) then longitude
    (E/W) each, as ``DD:MM:SS``, ``DD:MM.mmm`` or decimal degrees.

    Examples
    --------
    >>> parse_coordinates("f", "line 1", "51:30:00 N 000:07:30 W", 1)
    [(-0.125, 51.5)]
    >>> parse_coordinates("f", "line 2", "51:30.500N 000:07.500E, 51:31N 0:08E", 2)
    [(0.125, 51.50833333333333), (0.13333333333333333, 51.516666666666666)]
    """
    found = _COORD.findall(text)
    if len(found) != 2 * count:
        raise InputError(path, f"expected {count} lat/lon position(s), got {text.strip()!r}", where)
    out = []
    for k in range(count):
        lat = _degrees(path, where, found[2 * k], "NS", 90.0)
        lon = _degrees(path, where, found[2 * k + 1], "EW", 180.0)
        out.append((lon, lat))
    return out


def _degrees(path, where, parts, hemispheres, limit):
    deg, minutes, seconds, hemi = parts
    if hemi.upper() not in hemispheres:
        raise InputError(path, f"expected {'/'.join(hemispheres)} in {''.join(parts)!r}", where)
    m, s = float(minutes or 0), float(seconds or 0)
    if m >= 60 or s >= 60 or (seconds and "." in minutes):
        raise InputError(path, f"minutes and seconds must be below 60: {':'.join(parts)}", where)
    value = float(deg) + m / 60.0 + s / 3600.0
    if value > limit:
        raise InputError(path, f"{value:g} degrees is out of range", where)
    return -value if hemi.upper() in "SW" else value


def arc_from_points(path, where, centre, start, end, cw):
    """A ``DB`` arc about ``centre`` from ``start`` to ``end`` (lon, lat), clockwise when
    ``cw``: the part :func:`outline_polygon` takes.

    Raises
    ------
    InputError
        An end on the centre.
    """
    frame = LocalFrame(*centre)
    x, y = frame.to_local(np.array([start[0], end[0]]), np.array([start[1], end[1]]))
    r0, r1 = float(math.hypot(x[0], y[0])), float(math.hypot(x[1], y[1]))
    if min(r0, r1) <= 0:
        raise InputError(path, "an arc's end lies on its centre", where)
    b0, b1 = math.degrees(math.atan2(x[0], y[0])), math.degrees(math.atan2(x[1], y[1]))
    sweep = ((b1 - b0) if cw else (b0 - b1)) % 360.0
    return ("A", centre, r0, b0, r1, b1, cw, sweep, start, end)


def arc_from_angles(path, where, centre, radius_m, a0, a1, cw):
    """A ``DA`` arc about ``centre`` of ``radius_m`` from bearing ``a0`` to ``a1`` (degrees),
    clockwise when ``cw``: the part :func:`outline_polygon` takes.

    Raises
    ------
    InputError
        A radius that is not positive.
    """
    if not radius_m > 0:
        raise InputError(path, "an arc's radius must be positive", where)
    sweep = ((a1 - a0) if cw else (a0 - a1)) % 360.0
    if sweep == 0 and a0 != a1:
        sweep = 360.0
    frame = LocalFrame(*centre)
    b = np.radians([a0, a1])
    lons, lats = frame.to_wgs84(radius_m * np.sin(b), radius_m * np.cos(b))
    start, end = (float(lons[0]), float(lats[0])), (float(lons[1]), float(lats[1]))
    return ("A", centre, radius_m, a0, radius_m, a1, cw, sweep, start, end)


def _arc_points(arc, convex, exact):
    """Positions of an arc from its start to its end: sampled on the true arc (``exact``),
    outside it (``convex``: tangents) or inside it (chords)."""
    _, centre, r0, b0, r1, b1, cw, sweep, start, end = arc
    if sweep == 0:
        return [start, end]
    sign = 1.0 if cw else -1.0
    rmax, rmin = max(r0, r1), min(r0, r1)
    step = arc_step(rmax)
    n = max(1, math.ceil(sweep / step))
    step = sweep / n
    if exact:
        k = np.arange(1, n)
        radii = r0 + (r1 - r0) * k / n
        b = np.radians(b0 + sign * k * step)
        xy = np.column_stack([radii * np.sin(b), radii * np.cos(b)])
    elif convex:
        xy = circumscribed_points(rmax, b0 + sign * (np.arange(n) + 0.5) * step, step)
    else:
        b = np.radians(b0 + sign * np.arange(1, n) * step)
        r = max(rmin - PAD_M, 0.0)
        xy = np.column_stack([r * np.sin(b), r * np.cos(b)])
    lons, lats = LocalFrame(*centre).to_wgs84(xy[:, 0], xy[:, 1])
    return [start, *zip(np.atleast_1d(lons).tolist(), np.atleast_1d(lats).tolist()), end]


def _outline(parts, exact=False, ring_cw=None):
    pts = []
    for part in parts:
        if part[0] == "P":
            pts.append(part[1:])
        else:
            convex = ring_cw is None or part[6] == ring_cw
            pts.extend(_arc_points(part, convex, exact))
    return [p for i, p in enumerate(pts) if i == 0 or p != pts[i - 1]]


def outline_polygon(path, where, circle, parts):
    """An airspace's polygon: its ``DC`` circle, or its points and arcs, arcs drawn outward
    (by the ring's orientation).

    Parameters
    ----------
    path : str or Path
    where : str
        The airspace, for messages.
    circle : tuple or None
        ``(lon, lat, radius_m)`` of a ``DC``.
    parts : list of tuple
        ``("P", lon, lat)`` points and arcs from :func:`arc_from_points` and
        :func:`arc_from_angles`, in order.

    Returns
    -------
    (shapely.Polygon, dict)
        The polygon and its properties (``circle`` for a circle).

    Raises
    ------
    InputError
        A circle with other parts, or fewer than 3 distinct points.
    """
    if circle is not None:
        if parts:
            raise InputError(path, "a DC circle cannot be combined with DP, DA or DB", where)
        lon, lat, r = circle
        return circle_polygon(lon, lat, r), {"circle": [lon, lat, r]}
    sampled = _outline(parts, exact=True)
    if len(set(sampled)) < 3:
        raise InputError(path, "needs at least 3 distinct points (DP, DA, DB) or a DC", where)
    ring_cw = not shapely.LinearRing(sampled).is_ccw
    pts = _outline(parts, ring_cw=ring_cw)
    return shapely.Polygon(pts), {}
