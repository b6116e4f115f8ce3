"""Coordinate order and encoding, in one place.

GeoJSON and ED-269 store (lon, lat); QGroundControl plans and MAVLink store (lat, lon),
MAVLink as integers in 1e-7 degrees. Every reader and writer converts here and nowhere else.
"""

from __future__ import annotations

import math

import numpy as np

E7 = 10_000_000


def latlon(lonlat):
    """(lon, lat) pairs -> [lat, lon] lists (QGroundControl plan order).

    Examples
    --------
    >>> latlon([(14.5, 35.9), (14.6, 36.0)])
    [[35.9, 14.5], [36.0, 14.6]]
    """
    return [[float(lat), float(lon)] for lon, lat in np.asarray(lonlat, dtype=float).reshape(-1, 2)]


def lonlat_from_latlon(latlon_pairs):
    """[lat, lon] pairs (plan order) -> (n, 2) array of (lon, lat).

    Examples
    --------
    >>> lonlat_from_latlon([[35.9, 14.5]])
    array([[14.5, 35.9]])
    """
    arr = np.asarray(latlon_pairs, dtype=float).reshape(-1, 2)
    return arr[:, ::-1].copy()


def to_e7(deg):
    """Degrees -> MAVLink int32 in 1e-7 degrees (rounded to nearest).

    Examples
    --------
    >>> to_e7(35.89098)
    358909800
    """
    return int(round(float(deg) * E7))


def from_e7(value):
    """MAVLink int32 in 1e-7 degrees -> degrees.

    Examples
    --------
    >>> from_e7(358909800)
    35.89098
    """
    return int(value) / E7


def from_e7_float(value):
    """MAVLink 1e-7 degrees -> degrees, for a number or an array, as it is (``value / 1e7``).

    For values read off the link before they are checked: unlike :func:`from_e7` nothing is
    truncated to an integer, so a NaN or an infinity comes back as such (for the caller's
    range check) and a value that is not a number raises ``TypeError``.

    Examples
    --------
    >>> from_e7_float(358909800)
    35.89098
    >>> from_e7_float(np.array([1e7, -2.5e7]))
    array([ 1. , -2.5])
    """
    return value / E7


def quantize_e7(deg):
    """Degrees at MAVLink's resolution: rounded to the nearest 1e-7 degree.

    The same as ``from_e7(to_e7(deg))``: what a vehicle stores.

    Examples
    --------
    >>> quantize_e7(14.512345678)
    14.5123457
    """
    return from_e7(to_e7(deg))


def valid_lonlat(lon, lat) -> bool:
    """True when ``lon`` and ``lat`` are finite and within -180..180 and -90..90."""
    return (
        math.isfinite(lon)
        and math.isfinite(lat)
        and -180.0 <= lon <= 180.0
        and -90.0 <= lat <= 90.0
    )


def valid_lat(lat) -> bool:
    """True when ``lat`` is finite and within -90..90 (:func:`valid_lonlat`'s latitude test)."""
    return valid_lonlat(0.0, lat)


def valid_lon(lon) -> bool:
    """True when ``lon`` is finite and within -180..180 (:func:`valid_lonlat`'s longitude
    test)."""
    return valid_lonlat(lon, 0.0)


def checked_position(path, where, lat, lon):
    """``(lon, lat)`` as floats, or a one-line InputError naming ``path`` and ``where``.

    The one range check for positions read from plans, waypoint files and missions (which
    store lat, lon): non-numbers and coordinates out of range are refused.

    Parameters
    ----------
    path : str or Path
        The file, for the message.
    where : str
        The feature (``"line 4"``, ``"geoFence polygon 0"``), for the message.
    lat, lon : object
        The values as read.

    Returns
    -------
    tuple of float
        ``(lon, lat)``.
    """
    from alphafence.errors import InputError

    if not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        for v in (lat, lon)
    ):
        raise InputError(path, f"non-numeric position ({lat!r}, {lon!r})", where)
    if not valid_lonlat(lon, lat):
        raise InputError(path, f"coordinate (lat {lat}, lon {lon}) out of range", where)
    return float(lon), float(lat)


def check_lonlat_array(coords):
    """Index of the first invalid (lon, lat) row in an (n, 2) array, or None."""
    arr = np.asarray(coords, dtype=float).reshape(-1, 2)
    bad = ~(
        np.isfinite(arr).all(axis=1) & (np.abs(arr[:, 0]) <= 180.0) & (np.abs(arr[:, 1]) <= 90.0)
    )
    idx = np.flatnonzero(bad)
    return int(idx[0]) if idx.size else None
