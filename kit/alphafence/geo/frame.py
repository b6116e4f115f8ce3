"""Local metric frames: WGS84 (lon, lat) <-> metres east/north of an origin.

Alpha shapes, buffers, distances and areas are computed in metres, never in degrees.
Each frame is an azimuthal equidistant projection on the WGS84 ellipsoid centred near
the geometry it serves, so distortion over a site (a few km) is far below a centimetre.
A PROJ operation is used instead of a CRS pair: it is built in ~20 microseconds,
so every site can afford its own frame.

For a distance between two positions a few kilometres apart, where a frame is not worth
building, :func:`short_distance_m` is the one short-range formula.
"""

from __future__ import annotations

import math

import numpy as np
import pyproj
import shapely

EARTH_RADIUS_M = 6_371_000.0  # the mean radius: short-range distances and offsets
_RADIANS_PER_DEGREE = math.pi / 180.0  # PROJ's DEG_TO_RAD, what unitconvert scales by
_INVERSE = pyproj.enums.TransformDirection.INVERSE


def short_distance_m(a, b) -> float:
    """Horizontal metres between two ``(lat, lon)`` positions a few kilometres apart at most.

    The equirectangular approximation (one cosine at the mean latitude, the mean Earth
    radius): cheap enough for every position a monitor reads (GPS jumps, re-route legs,
    arrival at a waypoint), good to a fraction of a percent at that range.

    Parameters
    ----------
    a, b : tuple of float
        ``(lat, lon)`` in degrees (the order MAVLink reports positions in).

    Returns
    -------
    float

    Examples
    --------
    >>> round(short_distance_m((51.43, -0.55), (51.431, -0.55)), 2)
    111.19
    >>> round(short_distance_m((35.9, 14.5), (35.9, 14.51)), 1)
    900.7
    """
    dlat = math.radians(b[0] - a[0])
    dlon = math.radians(b[1] - a[1]) * math.cos(math.radians(0.5 * (a[0] + b[0])))
    return EARTH_RADIUS_M * math.hypot(dlat, dlon)


def wrap_lon(lon):
    """Longitudes into [-180, 180] (PROJ may return -180.00000000000003).

    Examples
    --------
    >>> wrap_lon(190.0)
    -170.0
    """
    lon = np.asarray(lon, float)
    out = np.where(np.abs(lon) > 180.0, (lon + 180.0) % 360.0 - 180.0, lon)
    return out if out.ndim else float(out)


class LocalFrame:
    """Metres east (x) and north (y) of an origin: an azimuthal equidistant projection on the
    WGS84 ellipsoid.

    Parameters
    ----------
    lon0, lat0 : float
        The origin, degrees.

    Examples
    --------
    >>> frame = LocalFrame(14.5, 35.9)
    >>> x, y = frame.to_local(14.51, 35.9)
    >>> round(float(x), 1), round(float(y), 1)
    (902.8, 0.0)
    >>> import shapely
    >>> round(frame.geom_to_local(shapely.box(14.5, 35.9, 14.51, 35.91)).area)
    1001630
    """

    __slots__ = ("lon0", "lat0", "_tr")

    def __init__(self, lon0: float, lat0: float):
        self.lon0 = float(lon0)
        self.lat0 = float(lat0)
        # the projection alone, half the cost of building the pipeline "unitconvert
        # xy_in=deg xy_out=rad, then aeqd", with the same numbers: pyproj multiplies degrees
        # by pi / 180 as unitconvert does, and to_wgs84 divides radians by it as unitconvert
        # does (multiplying by 180 / pi would differ in the last bit)
        self._tr = pyproj.Transformer.from_pipeline(
            f"+proj=aeqd +lat_0={self.lat0!r} +lon_0={self.lon0!r} +ellps=WGS84"
        )

    def __repr__(self):
        return f"LocalFrame(lon0={self.lon0:.6f}, lat0={self.lat0:.6f})"

    # -- arrays ---------------------------------------------------------------
    def to_local(self, lon, lat):
        """WGS84 ``lon``, ``lat`` (scalars or arrays, degrees) -> ``(x, y)`` in metres."""
        if type(lon) is float and type(lat) is float:  # one position (the monitor's): no arrays
            return self._tr.transform(lon, lat)
        return self._tr.transform(np.asarray(lon, float), np.asarray(lat, float))

    def to_wgs84(self, x, y):
        """``x``, ``y`` in metres (scalars or arrays) -> ``(lon, lat)`` in degrees, longitudes
        wrapped into [-180, 180].

        Examples
        --------
        >>> lon, lat = LocalFrame(14.5, 35.9).to_wgs84(0.0, 1000.0)
        >>> round(float(lon), 6), round(float(lat), 6)
        (14.5, 35.909012)
        """
        lon, lat = self._tr.transform(
            np.asarray(x, float), np.asarray(y, float), direction=_INVERSE, radians=True
        )
        return wrap_lon(lon / _RADIANS_PER_DEGREE), lat / _RADIANS_PER_DEGREE

    def jacobian(self, lon: float, lat: float, step_deg: float = 1e-5) -> tuple:
        """The frame's metres per degree at ``(lon, lat)``: ``(dx/dlon, dx/dlat, dy/dlon,
        dy/dlat)`` by central differences, so that a small displacement ``(dlon, dlat)`` is
        ``(x, y) = (j[0] dlon + j[1] dlat, j[2] dlon + j[3] dlat)`` metres (the monitor's reading
        of positions near a checked one: :mod:`alphafence.awareness.reach`).

        Examples
        --------
        >>> j = LocalFrame(14.5, 35.9).jacobian(14.5, 35.9)
        >>> [round(v, 1) + 0.0 for v in j]
        [90277.4, 0.0, 0.0, 110957.1]
        """
        e = step_deg
        x, y = self._tr.transform(
            np.array([lon + e, lon - e, lon, lon]), np.array([lat, lat, lat + e, lat - e])
        )
        h = 2.0 * e
        return (
            float((x[0] - x[1]) / h),
            float((x[2] - x[3]) / h),
            float((y[0] - y[1]) / h),
            float((y[2] - y[3]) / h),
        )

    def _fwd(self, coords):
        x, y = self._tr.transform(coords[:, 0], coords[:, 1])
        return np.column_stack([x, y])

    def _inv(self, coords):
        lon, lat = self._tr.transform(coords[:, 0], coords[:, 1], direction=_INVERSE, radians=True)
        return np.column_stack([wrap_lon(lon / _RADIANS_PER_DEGREE), lat / _RADIANS_PER_DEGREE])

    # -- geometries (scalars or arrays, vectorised) ---------------------------
    def geom_to_local(self, geom):
        """A WGS84 geometry (or array of them) in this frame's metres."""
        return shapely.transform(geom, self._fwd)

    def read_geom(self, geom, tolerance_m=0.05):
        """A WGS84 geometry (or array of them) in this frame's metres as its readers mean it:
        its edges straight lines in lon/lat (GeoJSON, QGroundControl, ArduPilot), followed to
        within ``tolerance_m`` (:func:`alphafence.geo.lonlat.densify_lonlat`), not the
        chords between its projected vertices.

        Examples
        --------
        >>> import shapely
        >>> frame = LocalFrame(10.5, 64.0)
        >>> strip = shapely.box(10.0, 63.99, 11.0, 64.0)  # 49 km along the parallel at 64°N
        >>> chords = frame.geom_to_local(strip)
        >>> round(chords.difference(frame.read_geom(strip)).area / 1e6, 2)  # km² cut off north
        3.13
        """
        from alphafence.geo.lonlat import densify_lonlat

        if isinstance(geom, np.ndarray):
            return self.geom_to_local(densify_lonlat(geom, tolerance_m).reshape(geom.shape))
        return self.geom_to_local(densify_lonlat([geom], tolerance_m)[0])

    def geom_to_wgs84(self, geom):
        """A geometry (or array of them) in this frame's metres back to WGS84 (lon, lat)."""
        return shapely.transform(geom, self._inv)

    @classmethod
    def around(cls, geom) -> LocalFrame:
        """A frame centred on the bounds of ``geom`` (WGS84), antimeridian-aware."""
        coords = shapely.get_coordinates(geom)
        return cls.around_coords(coords)

    @classmethod
    def around_coords(cls, coords) -> LocalFrame:
        """A frame centred on the bounds of ``(lon, lat)`` coordinates, antimeridian-aware.

        Examples
        --------
        >>> LocalFrame.around_coords([(14.5, 35.9), (14.51, 35.91)])
        LocalFrame(lon0=14.505000, lat0=35.905000)
        >>> LocalFrame.around_coords([(179.9, 0.0), (-179.9, 1.0)])
        LocalFrame(lon0=180.000000, lat0=0.500000)
        """
        coords = np.asarray(coords, float).reshape(-1, 2)
        lon = coords[:, 0]
        lat = coords[:, 1]
        lon0 = 0.5 * (lon.min() + lon.max())
        if lon.max() - lon.min() > 180.0:  # wraps the antimeridian
            wrapped = np.where(lon < 0, lon + 360.0, lon)
            lon0 = 0.5 * (wrapped.min() + wrapped.max())
            if lon0 > 180.0:
                lon0 -= 360.0
        lat0 = 0.5 * (lat.min() + lat.max())
        return cls(lon0, lat0)
