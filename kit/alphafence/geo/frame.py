"""Local metric frames: WGS84 (lon, lat) <-> metres east/north of an origin.

Alpha shapes, buffers, distances and areas are computed in metres, never in degrees.
Each frame is an azimuthal equidistant projection on the WGS84 ellipsoid centred near
the geometry it serves, so distortion over a site (a few km) is far below a centimetre.
A PROJ pipeline is used instead of a CRS pair: it is built in ~50 microseconds,
so every site can afford its own frame.
"""

from __future__ import annotations

import numpy as np
import pyproj
import shapely


def wrap_lon(lon):
    """Longitudes into [-180, 180] (PROJ may return -180.00000000000003)."""
    lon = np.asarray(lon, float)
    out = np.where(np.abs(lon) > 180.0, (lon + 180.0) % 360.0 - 180.0, lon)
    return out if out.ndim else float(out)


class LocalFrame:
    __slots__ = ("lon0", "lat0", "_tr")

    def __init__(self, lon0: float, lat0: float):
        self.lon0 = float(lon0)
        self.lat0 = float(lat0)
        self._tr = pyproj.Transformer.from_pipeline(
            "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
            f"+step +proj=aeqd +lat_0={self.lat0!r} +lon_0={self.lon0!r} +ellps=WGS84"
        )

    def __repr__(self):
        return f"LocalFrame(lon0={self.lon0:.6f}, lat0={self.lat0:.6f})"

    # -- arrays ---------------------------------------------------------------
    def to_local(self, lon, lat):
        return self._tr.transform(np.asarray(lon, float), np.asarray(lat, float))

    def to_wgs84(self, x, y):
        lon, lat = self._tr.transform(
            np.asarray(x, float),
            np.asarray(y, float),
            direction=pyproj.enums.TransformDirection.INVERSE,
        )
        return wrap_lon(lon), lat

    def _fwd(self, coords):
        x, y = self._tr.transform(coords[:, 0], coords[:, 1])
        return np.column_stack([x, y])

    def _inv(self, coords):
        lon, lat = self._tr.transform(
            coords[:, 0], coords[:, 1], direction=pyproj.enums.TransformDirection.INVERSE
        )
        return np.column_stack([wrap_lon(lon), lat])

    # -- geometries (scalars or arrays, vectorised) ---------------------------
    def geom_to_local(self, geom):
        return shapely.transform(geom, self._fwd)

    def geom_to_wgs84(self, geom):
        return shapely.transform(geom, self._inv)

    @classmethod
    def around(cls, geom) -> LocalFrame:
        """A frame centred on the bounds of ``geom`` (WGS84), antimeridian-aware."""
        coords = shapely.get_coordinates(geom)
        return cls.around_coords(coords)

    @classmethod
    def around_coords(cls, coords) -> LocalFrame:
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
