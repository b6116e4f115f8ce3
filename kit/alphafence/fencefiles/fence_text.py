"""Fence GeoJSON Features made from coordinate arrays, and made into what the writers need:
the compact JSON text of each Feature, its geometry as a shapely geometry.

``fence_geojson.fence_features`` takes every fence's coordinates together
(:func:`ring_structure`, :func:`wgs84_coordinates`) and returns a :class:`FenceFeatures`: the
Features (plain dicts, as any caller reads them) and the rounded coordinates they were made
of, as one array. From that array the coordinates' text is made without a ``repr`` per
number (vectorised: the digits of ``round(v, 8)`` are those of an integer number of 1e-8
degrees), and the WGS84 geometries without parsing the coordinate lists again.
:func:`feature_texts` and :func:`feature_geometries` take any list of Features and give
exactly what ``json.dumps`` and ``shapely.geometry.shape`` give for it: the arrays are used
only for a FenceFeatures whose Features still hold the geometry dicts they were made with.
"""

from __future__ import annotations

import gc
import json
from contextlib import contextmanager
from functools import cache

import numpy as np
import shapely

_ENCODE = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False).encode
_FEATURE_KEYS = ["type", "properties", "geometry"]
_CUT = ',"geometry":"\\u0000"}'  # a Feature's end, its geometry the string "\0"
_TYPES = {"Polygon": '"Polygon"', "MultiPolygon": '"MultiPolygon"'}
_SCALE = 1e8  # fence_geojson.DECIMALS places
_LOW, _HIGH = 10**4, 10**12  # whole 1e-8 units the text is made for: 1e-4 <= |v| < 1e4
# a point's text, 10 words of 4 bytes, NUL where a word has fewer characters:
# prefix | lon sign, integer, "." (2 words) | lon fraction (2) | "," lat (2) | lat fraction (2)
# | suffix ("]" for the point, one more per ring, part and multipolygon it ends)
_WORDS = 10
_PREFIX = ("[[[[", "[[[", ",[[[", ",[[", ",[")  # first of a MultiPolygon, Polygon, part, ring
_SUFFIX = ("]", "]]", "]]]", "]]]]")


class FenceFeatures(list):
    """GeoJSON fence Features (a list of dicts) and the arrays they were made of.

    Parameters
    ----------
    features : list of dict
        ``{"type": "Feature", "properties": ..., "geometry": ...}``, one per fence.
    local : numpy.ndarray
        Each fence's metric geometry (flat Polygons and MultiPolygons of non-empty parts).
    xy : numpy.ndarray
        ``(n, 2)``: every coordinate written, lon and lat rounded, in the order of
        ``shapely.get_coordinates(local)``.
    ring_sizes, ring_part, part_fence : numpy.ndarray
        Coordinates per ring; the part each ring belongs to; the fence each part belongs to.

    Notes
    -----
    The arrays describe the geometries as made: a Feature whose ``"geometry"`` is replaced
    is written from its dict, but coordinates changed in place inside the lists would not be
    seen (nothing in the kit does that).
    """

    def __init__(self, features, local, xy, ring_sizes, ring_part, part_fence):
        super().__init__(features)
        self._geometries = [f["geometry"] for f in features]
        self._arrays = (local, xy, ring_sizes, ring_part, part_fence)

    def _intact(self):
        geometries = self._geometries
        return len(self) == len(geometries) and all(
            type(f) is dict
            and list(f) == _FEATURE_KEYS
            and f["type"] == "Feature"
            and f["geometry"] is g
            and len(g) == 2
            for f, g in zip(self, geometries)
        )

    def __reduce__(self):  # pickled as the plain list it is
        return list, (list(self),)


@contextmanager
def paused_gc():
    """No cyclic garbage collection inside: for code making many small lists, dicts and
    strings with no reference cycles among them, which the collector would only walk again
    and again with the whole heap (twice the time)."""
    collect = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collect:
            gc.enable()


def ring_structure(local, kinds):
    """How metric fence geometries are made of rings, if they are flat Polygons and
    MultiPolygons of non-empty parts. Polygons without holes (nearly every fence) are their
    own part and ring: then no part or ring is copied out of GEOS.

    Parameters
    ----------
    local : numpy.ndarray of shapely geometries
    kinds : numpy.ndarray
        Their ``shapely.get_type_id``.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray) or None
        Coordinates per ring, the part each ring belongs to, the geometry each part belongs
        to; None for any other geometry.
    """
    if not np.all((kinds == 3) | (kinds == 6)) or np.any(shapely.has_z(local)):
        return None
    if np.all(shapely.get_num_interior_rings(local) == 0) and np.all(kinds == 3):
        if np.any(shapely.is_empty(local)):
            return None
        index = np.arange(len(local))
        return shapely.get_num_coordinates(local), index, index
    parts, owner = shapely.get_parts(local, return_index=True)
    if np.any(shapely.is_empty(parts)):
        return None
    rings, ring_part = shapely.get_rings(parts, return_index=True)
    return shapely.get_num_coordinates(rings), ring_part, owner


def wgs84_coordinates(fences, local_xy, ends):
    """Built fences' metric coordinates in WGS84, exactly as each one's ``frame.to_wgs84``
    gives them: each run of fences sharing one frame (a site's) transformed at once; for
    LocalFrames in place, the radians turned into degrees and the longitudes wrapped for all
    runs together.

    Parameters
    ----------
    fences : list of Fence
    local_xy : numpy.ndarray
        ``(n, 2)``: every fence's coordinates, fence after fence, metres.
    ends : list of int
        Where each fence's coordinates end in ``local_xy``.

    Returns
    -------
    numpy.ndarray
        ``(n, 2)`` lon, lat.
    """
    from alphafence.geo.frame import _INVERSE, _RADIANS_PER_DEGREE, LocalFrame, wrap_lon

    x, y = np.ascontiguousarray(local_xy[:, 0]), np.ascontiguousarray(local_xy[:, 1])
    local_frames = all(type(f.frame) is LocalFrame for f in fences)
    start, last = 0, len(fences) - 1
    for k, f in enumerate(fences):
        frame = f.frame
        if k < last and fences[k + 1].frame is frame:
            continue
        stop = ends[k]
        if local_frames:  # LocalFrame.to_wgs84's own transformation, then its scaling below
            frame._tr.transform(
                x[start:stop], y[start:stop], direction=_INVERSE, radians=True, inplace=True
            )
        else:
            x[start:stop], y[start:stop] = frame.to_wgs84(x[start:stop], y[start:stop])
        start = stop
    if local_frames:
        x, y = wrap_lon(x / _RADIANS_PER_DEGREE), y / _RADIANS_PER_DEGREE
    return np.column_stack([x, y])


def feature_texts(features) -> list:
    """Each Feature as compact JSON (``json.dumps`` with ``separators=(",", ":")`` and
    ``ensure_ascii=False``), the same text whichever way it is made.

    Parameters
    ----------
    features : list of dict

    Returns
    -------
    list of str

    Examples
    --------
    >>> feature_texts([{"type": "Feature", "properties": {"name": "Ħ"}, "geometry": None}])
    ['{"type":"Feature","properties":{"name":"Ħ"},"geometry":null}']
    """
    with paused_gc():
        return _texts(features)


def _texts(features):
    coordinates = _coordinates_texts(features)
    if coordinates is None:
        return [_ENCODE(f) for f in features]
    # the properties of all in one encoding, cut where each Feature's geometry goes
    marked = [
        {"type": "Feature", "properties": f["properties"], "geometry": "\0"} for f in features
    ]
    heads = _ENCODE(marked)[1:].split(_CUT)
    if len(heads) != len(features) + 1:  # a property's text has the cut in it
        heads = [_ENCODE(f)[: -len(_CUT)] for f in marked]
    else:
        heads[1:-1] = [h[1:] for h in heads[1:-1]]  # the commas between them
    return [
        f'{head},"geometry":{{"type":{_TYPES.get(g["type"]) or _ENCODE(g["type"])},'
        f'"coordinates":{text}}}}}'
        for head, g, text in zip(heads, features._geometries, coordinates)
    ]


def feature_geometries(features) -> np.ndarray:
    """Each Feature's geometry as ``shapely.geometry.shape`` makes it (lon, lat).

    Parameters
    ----------
    features : list of dict

    Returns
    -------
    numpy.ndarray of shapely geometries
    """
    out = np.empty(len(features), dtype=object)
    if isinstance(features, FenceFeatures) and len(features) and features._intact():
        local, xy = features._arrays[:2]
        out[:] = shapely.transform(local, lambda _: xy)
    else:
        out[:] = [shapely.geometry.shape(f["geometry"]) for f in features]
    return out


def _coordinates_texts(features):
    """The ``"coordinates"`` text of each Feature of a FenceFeatures, or None (not one, or
    not as made, or a number whose text is not made here)."""
    if not (isinstance(features, FenceFeatures) and len(features) and features._intact()):
        return None
    _, xy, ring_sizes, ring_part, part_fence = features._arrays
    if np.bincount(part_fence, minlength=len(features)).min() == 0:
        return None  # an empty MultiPolygon
    rows = _number_words(xy)
    if rows is None:
        return None
    multi = np.array([g["type"] == "MultiPolygon" for g in features._geometries])
    ring_fence = part_fence[ring_part]
    rings = len(ring_sizes)
    ring_start = np.cumsum(ring_sizes) - ring_sizes
    new_part = np.ones(rings, bool)
    new_part[1:] = ring_part[1:] != ring_part[:-1]
    new_fence = np.ones(rings, bool)
    new_fence[1:] = ring_fence[1:] != ring_fence[:-1]
    end_part = np.ones(rings, bool)
    end_part[:-1] = new_part[1:]
    end_fence = np.ones(rings, bool)
    end_fence[:-1] = new_fence[1:]
    prefix = np.full(len(xy), 4, np.int64)
    prefix[ring_start] = np.where(
        new_fence, np.where(multi[ring_fence], 0, 1), np.where(new_part, 2, 3)
    )
    suffix = np.zeros(len(xy), np.int64)
    suffix[ring_start + ring_sizes - 1] = 1 + end_part + (end_part & end_fence & multi[ring_fence])
    rows[:, 0] = _tables()["prefix"][prefix]
    rows[:, 9] = _tables()["suffix"][suffix]
    data = rows.tobytes()
    width = 4 * _WORDS
    ends = (np.cumsum(np.bincount(ring_fence, ring_sizes, len(features))) * width).astype(int)
    out, start = [], 0
    for end in ends.tolist():
        out.append(data[start:end].translate(None, b"\0").decode("ascii"))
        start = end
    return out


def _number_words(xy):
    """``(n, 10)`` uint32 words of each point's text (words 0 and 9 left for the caller), or
    None if a number is not one whose ``repr`` is made here: finite, ``k / 1e8`` exactly for
    an integer k, ``1e-4 <= |v| < 1e4`` (``repr`` writes those as digits, a point and at
    most 8 decimals, trailing zeros dropped but one)."""
    k = np.rint(xy * _SCALE)
    with np.errstate(invalid="ignore"):
        a = np.abs(k)
        if not (np.all(k / _SCALE == xy) and np.all((a >= _LOW) & (a < _HIGH))):
            return None
    a = a.astype(np.int64)
    whole, frac = np.divmod(a, 10**8)
    hi, lo = np.divmod(frac, 10**4)
    t = _tables()
    whole_at = whole + (k < 0) * 10**4
    frac_hi = np.where(lo == 0, t["stripped_hi"][hi], t["digits"][hi])
    frac_lo = t["stripped"][lo]
    rows = np.empty((len(xy), _WORDS), np.uint32)
    rows[:, 1:3] = t["whole"][whole_at[:, 0]]
    rows[:, 3], rows[:, 4] = frac_hi[:, 0], frac_lo[:, 0]
    rows[:, 5:7] = t["comma_whole"][whole_at[:, 1]]
    rows[:, 7], rows[:, 8] = frac_hi[:, 1], frac_lo[:, 1]
    return rows


@cache
def _tables():
    """Words of text, NUL-padded: 4 characters as uint32, 8 as two."""

    def words(texts, size, right=False):
        raw = b"".join(
            t.encode("ascii").rjust(size, b"\0") if right else t.encode("ascii").ljust(size, b"\0")
            for t in texts
        )
        return np.frombuffer(raw, np.uint32).reshape(len(texts), size // 4)

    digits = [f"{i:04d}" for i in range(10**4)]
    whole = [f"{sign}{i}." for sign in ("", "-") for i in range(10**4)]
    return {
        "digits": words(digits, 4)[:, 0],
        "stripped": words([d.rstrip("0") for d in digits], 4)[:, 0],
        "stripped_hi": words([d.rstrip("0") or "0" for d in digits], 4)[:, 0],
        "whole": words(whole, 8, right=True),
        "comma_whole": words(["," + w for w in whole], 8, right=True),
        "prefix": words(_PREFIX, 4, right=True)[:, 0],
        "suffix": words(_SUFFIX, 4)[:, 0],
    }
