"""Fences that hold as they are read: every polygon a build writes contains its restricted area
plus margin when its edges are straight lon/lat lines (GeoJSON, QGroundControl, ArduPilot),
not only in the site's metric frame where it was made.

The fences are made in the metric frame; here each one whose edges are long enough to bow
(:func:`alphafence.geo.lonlat.bow_free`) is held outward (keep-out and warning fences) or
inward (keep-in) by :func:`alphafence.geo.hold.hold_as_read`, and checked again as read.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from alphafence.geo.alpha import fill_holes
from alphafence.geo.hold import hold_as_read
from alphafence.geo.lonlat import (
    EARTH_RADIUS_M,
    MAX_LAT,
    METRES_PER_DEGREE,
    READ_TOLERANCE_M,
    ZONE_TOLERANCE_M,
    as_read,
    bow_free_one,
    frame_scale,
    unwrap_lon,
)
from alphafence.geo.rings import clear_of

# what the lon/lat readings may leave: the zone's densified edges and the check's own
READ_SLACK_M = ZONE_TOLERANCE_M + READ_TOLERANCE_M
WIDE_REACH_M = 20_000.0  # within this of its frame's origin a margin widens by under 1e-6


def ground_margins(geoms, margins):
    """Each margin widened by its frame's scale where the site reaches far from the frame's
    origin (an azimuthal equidistant frame reads distances across its radius too long: a
    700 km site's 100 m margin is 0.2 m short on the ground unless widened). Margins of
    sites whose widening is below a millimetre come back as they are.

    Parameters
    ----------
    geoms : sequence of shapely geometry
        The sites' restricted areas, metres in their frames.
    margins : sequence of float

    Returns
    -------
    list of float
    """
    out = list(margins)
    if len(out) == 1:  # the usual call: one site
        x0, y0, x1, y1 = geoms[0].bounds
        if not math.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))) > WIDE_REACH_M:
            return out
    if not len(out):
        return out
    b = shapely.bounds(np.asarray(geoms, dtype=object))
    reach = np.hypot(np.fmax(np.abs(b[:, 0]), np.abs(b[:, 2])),
                     np.fmax(np.abs(b[:, 1]), np.abs(b[:, 3])))  # fmt: skip
    for i in np.flatnonzero(reach > WIDE_REACH_M).tolist():  # NaN (empty): not
        m, r = out[i], float(reach[i])
        if m > 0:
            wide = m * frame_scale(r + m)
            if wide - m > 1e-3:
                out[i] = wide
    return out


def clear_as_read(local, frame, zone, margin_m) -> bool:
    """Whether a fence's lon/lat reading is proven to contain ``zone`` with ``margin_m``
    around it (and the readings' tolerances) without reading it: each edge keeps from the
    zone the margin plus the most its reading can bow (:func:`bow_bound_length_m`'s bound,
    ``L^2 (tan|lat| + 1) / 8R`` at the fence's farthest latitude), and the fence covers it.

    Edge by edge, so the long edges of a fence (whose bows are largest) are held only where
    they run close to the zone: a fence that passes needs no holding and no reading.

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(14.5, 35.9)
    >>> zone = shapely.box(0, 0, 1000, 10)
    >>> clear_as_read(shapely.box(-50, -50, 1050, 60), frame, zone, 49.8)
    True
    >>> clear_as_read(shapely.box(-50, -50, 1050, 60), frame, zone, 49.95)  # bows 4 cm
    False
    """
    if not shapely.covers(local, zone):
        return False
    rings = shapely.get_rings(shapely.get_parts(local))
    coords, which = shapely.get_coordinates(rings, return_index=True)
    same = which[1:] == which[:-1]
    a, b = coords[:-1][same], coords[1:][same]
    reach = float(np.abs(coords).max()) if len(coords) else 0.0
    lat = min(abs(frame.lat0) + reach / METRES_PER_DEGREE, MAX_LAT)
    length = np.hypot(*(b - a).T)
    bow = length**2 * (math.tan(math.radians(lat)) + 1.0) / (8.0 * EARTH_RADIUS_M)
    edges = shapely.linestrings(np.stack([a, b], axis=1))
    return bool(np.all(shapely.distance(edges, zone) >= margin_m + READ_SLACK_M + bow))


def hold_fences(locals_, frames, outward=True, regions=None, zones=None):
    """Each fence held so that its lon/lat reading contains (``outward``) or stays inside
    what it contains in its frame; fences whose edges cannot bow come back as they are.

    A fence whose lon/lat reading is no polygon at all (a vertex a simplification moved so
    far that its edges would read across half the world) is replaced by its region
    (``regions[i]``, its holes filled), held in turn.

    Parameters
    ----------
    locals_ : sequence of shapely geometry
        Metres, each in its frame.
    frames : sequence of LocalFrame
    outward : bool
    regions : sequence of shapely geometry, optional
        What each fence must contain, metres (outward holds only).
    zones : tuple of sequences, optional
        ``(geometries, margins)``: each fence's restricted area and margin (outward holds
        only); a fence :func:`clear_as_read` of them is not held (nor changed).

    Returns
    -------
    list of shapely geometry
    list of bool
        Which fences were changed.
    """
    out = list(locals_)
    changed = [False] * len(out)
    free = bow_free_many(out, frames)
    for i, (geom, frame) in enumerate(zip(out, frames)):
        if free[i] or bow_free_one(geom, frame):
            continue
        if zones is not None and clear_as_read(geom, frame, zones[0][i], zones[1][i]):
            continue
        if regions is not None and not readable(geom, frame):  # before holding: it cannot
            geom = fill_holes(regions[i])
        held = hold_as_read(geom, frame, outward)
        if regions is not None and not readable(held, frame):
            held = hold_as_read(fill_holes(regions[i]), frame, outward)
        if held is not out[i]:
            out[i], changed[i] = held, True
    return out, changed


def bow_free_many(geoms, frames):
    """Which fences cannot bow by their bounds' diagonal alone (:func:`bow_free_one`'s first
    test, for all of them at once; None counts as free); the others are measured one by one.

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(14.5, 35.9)  # the bound there: 543 m
    >>> bow_free_many([shapely.box(0, 0, 300, 300), shapely.box(0, 0, 3000, 300), None],
    ...               [frame] * 3).tolist()
    [True, False, True]
    """
    if not len(geoms):
        return np.zeros(0, bool)
    b = shapely.bounds(np.array(geoms, dtype=object))  # NaN for None and empty: free
    reach = np.fmax(np.fmax(np.abs(b[:, 0]), np.abs(b[:, 1])),
                    np.fmax(np.abs(b[:, 2]), np.abs(b[:, 3])))  # fmt: skip
    lat = np.fmin(np.abs([f.lat0 for f in frames]) + reach / METRES_PER_DEGREE, MAX_LAT)
    bound = np.sqrt(8.0 * EARTH_RADIUS_M * READ_TOLERANCE_M / (np.tan(np.radians(lat)) + 1.0))
    # a hair inside the bound: numpy's and math's last digits may differ; those few are
    # measured one by one, as ever
    return ~(np.hypot(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]) > bound * (1 - 1e-9))


def readable_fences(locals_, frames, regions, simplify, budget):
    """Fences whose lon/lat reading is no polygon (a simplification moved a vertex so far
    that the edges read across each other) simplified again from their regions with twice
    the vertices, until they read as polygons (else their regions as they are).

    Parameters
    ----------
    locals_, frames, regions : sequences
        The fences (metres), their frames and the regions they were simplified from.
    simplify : callable
        ``simplify(region, max_vertices)`` -> the fence.
    budget : int
        The vertices they were simplified to.

    Returns
    -------
    list of shapely geometry
    """
    out = list(locals_)
    for i, (geom, frame) in enumerate(zip(out, frames)):
        if geom is None or bow_free_one(geom, frame) or readable(geom, frame):
            continue
        n, geom = budget, fill_holes(regions[i])
        for _ in range(8):
            n *= 2
            again = simplify(regions[i], n)
            if readable(again, frame):
                geom = again
                break
        out[i] = geom
    return out


def readable(local, frame) -> bool:
    """Whether a metric polygon's lon/lat vertices make a polygon when read as straight
    lon/lat lines: no edge longer than 180° of longitude, and valid as read.

    Examples
    --------
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(0.0, -44.0)
    >>> readable(shapely.box(0, 0, 50_000, 50_000), frame)
    True
    >>> readable(shapely.Polygon([(-1.2e7, 0), (1.2e7, 0), (0, 1e5)]), frame)  # 12,000 km
    False
    """
    for part in shapely.get_parts(local).tolist():
        for ring in (part.exterior, *part.interiors):
            c = np.asarray(ring.coords)
            lon, lat = frame.to_wgs84(c[:, 0], c[:, 1])
            lon = unwrap_lon(np.asarray(lon))
            if np.ptp(lon) >= 180.0 or not shapely.LinearRing(np.column_stack([lon, lat])).is_valid:
                return False
    return True


def reads_covering(local, frame, geometry, margin_m) -> bool:
    """Whether ``local``'s lon/lat reading contains ``geometry`` with ``margin_m`` around it
    and the readings' tolerances beyond it (the zone's densified edges, the check's own),
    checked in ``frame``'s metres.

    Parameters
    ----------
    local : shapely geometry
        The fence, metres.
    frame : LocalFrame
    geometry : shapely geometry
        The restricted area, metres.
    margin_m : float

    Returns
    -------
    bool
    """
    read = as_read(frame.geom_to_wgs84(local), frame)
    read = shapely.make_valid(read) if not read.is_valid else read
    if not shapely.covers(read, geometry):
        return False
    return clear_of(shapely.boundary(read), geometry, margin_m + READ_SLACK_M)


def split_at_antimeridian(fences):
    """Fences that reach across ±180° of longitude, split into a part on each side
    (RFC 7946 §3.1.9): ArduPilot and every lon/lat reader join vertices without wrapping, so
    one ring from 179.99° to -179.99° would span the world. The split is made on the lon/lat
    reading itself (each edge crossing the antimeridian cut where its straight lon/lat line
    meets it), so the parts read together exactly as the whole did; the parts' shared edges
    run along the meridian, straight in lon/lat. The split geometry becomes the fence's
    ``wgs84``. Fences far from the antimeridian are not looked at.

    Parameters
    ----------
    fences : list of Fence

    Returns
    -------
    list of Fence
        The same fences, those across the antimeridian with their parts set.
    """
    if not fences:
        return fences
    b = np.abs(shapely.bounds(np.array([f.local for f in fences], dtype=object)))
    ok = np.isfinite(b).all(axis=1)
    reach = np.where(ok, np.fmax.reduce(np.where(ok[:, None], b, 0.0), axis=1), 0.0)
    lat0 = np.abs([f.frame.lat0 for f in fences])
    lon0 = np.abs([f.frame.lon0 for f in fences])
    scale = np.fmax(np.cos(np.radians(np.fmin(lat0 + reach / 111_000.0, 89.9))), 1e-3)
    for i in np.flatnonzero(~(lon0 + reach / (111_000.0 * scale) < 179.0)).tolist():
        split = split_lonlat(fences[i].geometry)
        if split is not None:
            fences[i].wgs84 = split
    return fences


def split_lonlat(geom):
    """A lon/lat polygon whose rings step across ±180° (read the short way) split into parts
    on each side, or None when it does not cross.

    Examples
    --------
    >>> square = shapely.box(179.99, 0.0, 180.01, 0.01)  # as a frame writes it: wrapped
    >>> wrapped = shapely.Polygon([(179.99, 0), (-179.99, 0), (-179.99, 0.01), (179.99, 0.01)])
    >>> [p.bounds for p in split_lonlat(wrapped).geoms]
    [(179.99, 0.0, 180.0, 0.01), (-180.0, 0.0, -179.99, 0.01)]
    """
    parts = shapely.get_parts(geom)
    crossing = False
    moved = []
    for part in parts.tolist():
        rings = [part.exterior, *part.interiors]
        out = []
        for ring in rings:
            c = np.asarray(ring.coords)[:, :2]
            lon = unwrap_lon(c[:, 0])
            crossing |= bool(lon.max() > 180.0 or lon.min() < -180.0)
            if lon.min() < -180.0:
                lon = lon + 360.0
            out.append(np.column_stack([lon, c[:, 1]]))
        moved.append(shapely.Polygon(out[0], out[1:]))
    if not crossing:
        return None
    whole = shapely.union_all(moved)
    east = shapely.intersection(whole, shapely.box(-180.0, -90.0, 180.0, 90.0))
    west = shapely.intersection(whole, shapely.box(180.0, -90.0, 540.0, 90.0))
    west = shapely.transform(west, lambda c: c - np.array([360.0, 0.0]))
    pieces = [
        p for g in (east, west) for p in shapely.get_parts(g).tolist() if p.geom_type == "Polygon"
    ]
    return shapely.MultiPolygon(pieces)
