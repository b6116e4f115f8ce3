"""Onboard fence items from the chosen options: coordinates rounded to MAVLink's 1e-7
degrees, and every polygon re-checked after rounding."""

from __future__ import annotations

import math

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.fencing.as_read import split_lonlat
from alphafence.geo.coords import quantize_e7
from alphafence.geo.hold import hold_as_read
from alphafence.geo.lonlat import READ_TOLERANCE_M, as_read, frame_scale
from alphafence.geo.vehicle_distance import circle_radius
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
)
from alphafence.onboard.options import PAD_M, own_option


def _round_lonlat(frame, xy):
    lon, lat = frame.to_wgs84(np.asarray(xy)[:, 0], np.asarray(xy)[:, 1])
    lon = np.array([quantize_e7(v) for v in np.atleast_1d(lon)])
    lat = np.array([quantize_e7(v) for v in np.atleast_1d(lat)])
    return lon, lat


def _covers(outer, inner, slack_m=READ_TOLERANCE_M + 0.01):
    """``outer`` covers ``inner`` but for slivers thinner than ``slack_m`` (bows left as
    they are, rounding to 1e-7 degrees) that the pieces' own pad absorbs."""
    if outer.covers(inner):
        return True
    return shapely.buffer(outer, slack_m, join_style="mitre").covers(inner)


def _sides(lon, lat):
    """A ring's vertices, or its parts on each side of the antimeridian when it steps
    across it (:func:`~alphafence.fencing.as_read.split_lonlat`), each counter-clockwise."""
    ring = np.column_stack([lon, lat])
    if np.ptp(lon) <= 180.0:
        return [ring.tolist()]
    parts = split_lonlat(shapely.Polygon(ring))
    out = []
    for part in parts.geoms:
        pts = np.asarray(shapely.LinearRing(part.exterior).coords)[:-1]
        if not shapely.LinearRing(pts).is_ccw:
            pts = pts[::-1]
        out.append([(quantize_e7(a), quantize_e7(b)) for a, b in pts])
    return out


def held_lonlat(local, frame, grows, target):
    """``local``'s exterior held as read (:func:`~alphafence.geo.hold.hold_as_read`: outward
    when it ``grows``, else inward), counter-clockwise, rounded to 1e-7 degrees: ``(lon,
    lat, ok)``, ``ok`` saying whether that ring, read as lon/lat lines, contains ``target``
    (lies inside it, when it does not grow)."""
    held = hold_as_read(shapely.Polygon(local.exterior), frame, outward=grows)
    ring = shapely.LinearRing(held.exterior)
    pts = np.asarray(ring.coords)[:-1]
    if not ring.is_ccw:
        pts = pts[::-1]
    lon, lat = _round_lonlat(frame, pts)
    check = as_read(shapely.Polygon(np.column_stack([lon, lat])), frame)
    ok = check.is_valid and (_covers(check, target) if grows else _covers(target, check))
    return lon, lat, ok


def emit_items(pieces, frame, return_point=None, autopilot="ardupilot"):
    """The fence items of the pieces' chosen options, in upload order.

    The return point first, then inclusions, then exclusion polygons, then circles. Polygons
    run counter-clockwise; circle radii are rounded up to the centimetre, plus one.

    Parameters
    ----------
    pieces : list of Piece
    frame : LocalFrame
        The frame the pieces are in.
    return_point : tuple, optional
        ``(lon, lat)`` of the fence's return point.
    autopilot : str
        Whose circle distance the radii are for (``"ardupilot"`` or ``"px4"``).

    Returns
    -------
    list of FenceItem

    Raises
    ------
    InputError
        If rounding a polygon to 1e-7 degrees broke its containment (a bug).
    """
    items = []
    if return_point is not None:
        items.append(
            FenceItem(RETURN_POINT, 0.0, quantize_e7(return_point[0]), quantize_e7(return_point[1]))
        )
    for p in sorted(pieces, key=lambda p: (not p.inclusion, p.chosen.kind == "circle")):
        o = p.chosen
        if o.kind == "circle":
            x, y, r = o.circle
            lon, lat = _round_lonlat(frame, [(x, y)])
            # the geodesic radius (the frame reads a little long off its origin), then the
            # radius the autopilot's own distance needs to contain it
            r = circle_radius(autopilot, lon[0], lat[0], r * frame_scale(math.hypot(x, y) + r))
            items.append(
                FenceItem(
                    CIRCLE_EXCLUSION,
                    float(math.ceil(r * 100) / 100 + 0.01),
                    float(lon[0]),
                    float(lat[0]),
                )
            )
            continue
        # held so that its lon/lat reading (ArduPilot's) contains what the polygon contains,
        # or lies inside it for an inclusion that must not grow
        lon, lat, ok = held_lonlat(o.local, frame, p.grows, p.local)
        if not ok:
            raise InputError(
                "compile",
                f"fence {', '.join(p.sources)}: rounding to 1e-7 degrees or reading its edges "
                "as lon/lat lines broke containment; please report this",
            )
        cmd = POLYGON_INCLUSION if p.inclusion else POLYGON_EXCLUSION
        for part in _sides(lon, lat):  # ArduPilot never wraps: a part on each side of 180°
            items.extend(FenceItem(cmd, float(len(part)), float(a), float(b)) for a, b in part)
    return items


def own_held(rec, part, frame, max_vertices):
    """The option of storing ``rec`` as its own vertices (:func:`own_option`), when ``part``,
    its reading, has vertices along bowed edges, and only if that option, held as read and
    rounded, holds the fence (None otherwise)."""
    geom = rec.geometry
    if geom.geom_type != "Polygon" or shapely.get_num_coordinates(geom) > 4 * max_vertices:
        return None
    lon = shapely.get_coordinates(geom.exterior)[:, 0]
    if lon.max() - lon.min() > 180.0:  # across the antimeridian: as read, in parts
        return None
    own = shapely.Polygon(frame.geom_to_local(shapely.Polygon(geom.exterior)).exterior)
    inclusion = rec.kind == "keep_in"
    opt = own_option(own, part, inclusion, max_vertices)
    if opt is None:
        return None
    lon, lat, ok = held_lonlat(opt.local, frame, not inclusion, part)
    if not ok:
        return None
    # held against its own chords, not the fence: it must stand half its pad clear of it
    read = as_read(shapely.Polygon(np.column_stack([lon, lat])), frame)
    if inclusion:
        ok = part.covers(shapely.buffer(read, PAD_M / 2, join_style="mitre"))
    else:
        ok = read.covers(shapely.buffer(part, PAD_M / 2, join_style="mitre"))
    return opt if ok else None
