"""Onboard fence items back into fences: what the vehicle holds, as geometry.

A vehicle's fence (downloaded, or read from a plan) is a flat list of MAV_CMD_NAV_FENCE_*
items: a polygon is ``n`` consecutive vertices of one command, each carrying ``n``; a circle
is one item with its radius in metres; the return point is not a fence. :func:`decode_fence`
checks the list as ArduPilot's loader does (``AC_PolyFence_loader::validate_fence``) and
returns one :class:`OnboardFence` per polygon or circle, named after the items it came from,
so a monitor can say which item it is about to hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.geo.coords import valid_lonlat
from alphafence.geo.frame import LocalFrame
from alphafence.geo.vehicle_distance import (
    LATLON_TO_M,
    polygon_outside,
    vehicle_circle_rim,
    vehicle_distance_m,
)
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    MAX_POLYGON_VERTICES,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
)

POLYGONS = (POLYGON_INCLUSION, POLYGON_EXCLUSION)
CIRCLES = (CIRCLE_INCLUSION, CIRCLE_EXCLUSION)
INCLUSIONS = (POLYGON_INCLUSION, CIRCLE_INCLUSION)
CIRCLE_SEGMENTS = 64  # a circle as a polygon of this many sides
MAX_RADIUS_M = 1e7  # a larger circle radius is not a fence (the Earth is smaller)


@dataclass(frozen=True)
class OnboardFence:
    """One polygon or circle of a vehicle's fence.

    Attributes
    ----------
    inclusion : bool
        An inclusion (the vehicle must stay inside) or an exclusion (it must stay out).
    shape : str
        ``"polygon"`` or ``"circle"``.
    number : int
        1-based among the fences of the same kind and shape (``exclusion circle 5`` is the
        fifth exclusion circle), in item order.
    first, last : int
        The item sequence numbers (0-based, as MAVLink numbers them) it came from.
    lonlat : tuple of tuple
        The polygon's vertices ``(lon, lat)``, or the circle's centre alone.
    radius_m : float, optional
        The circle's radius.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> fences = decode_fence([FenceItem(5000, 0.0, 14.5, 35.9), FenceItem(5004, 60.0, 14.5, 35.9)])
    >>> fences[0].name
    'onboard exclusion circle 1 (item 1)'
    """

    inclusion: bool
    shape: str
    number: int
    first: int
    last: int
    lonlat: tuple
    radius_m: float | None = None

    @property
    def wraps(self) -> bool:
        """A polygon whose vertices span more than 180° of longitude: ArduPilot never wraps,
        so it reads the polygon the long way round the world, not across the antimeridian."""
        return (
            self.shape == "polygon"
            and max(x for x, _ in self.lonlat) - min(x for x, _ in self.lonlat) > 180.0
        )

    @property
    def kind(self) -> str:
        """``"exclusion"`` or ``"inclusion"``."""
        return "inclusion" if self.inclusion else "exclusion"

    @property
    def items(self) -> str:
        """The items it came from in words: ``"item 46"`` or ``"items 10-45"``."""
        if self.first == self.last:
            return f"item {self.first}"
        return f"items {self.first}-{self.last}"

    @property
    def name(self) -> str:
        """What the operator reads: ``"onboard exclusion polygon 2 (items 10-45)"``."""
        return f"onboard {self.kind} {self.shape} {self.number} ({self.items})"

    @property
    def short_name(self) -> str:
        """For a 50-character STATUSTEXT: ``"excl poly 2 #10-45"``, ``"incl circle 1 #3"``."""
        shape = "poly" if self.shape == "polygon" else "circle"
        items = str(self.first) if self.first == self.last else f"{self.first}-{self.last}"
        return f"{self.kind[:4]} {shape} {self.number} #{items}"

    def geometry(self, segments: int = CIRCLE_SEGMENTS):
        """The area the fence bounds, WGS84 (lon, lat), as a polygon the monitor can index.

        A polygon is made valid the way ArduPilot reads one (even-odd: a bow-tie is its two
        lobes); what has no area (all vertices on a line) is empty. A circle is a polygon of
        ``segments`` sides drawn as ArduPilot measures distance (its flat-earth
        ``Location::get_distance``: an ellipse in lon/lat), erring to the safe side: an
        exclusion's polygon contains the circle (its sides touch it), an inclusion's lies
        within it (its vertices are on it). A polygon whose vertices span more than 180° of
        longitude is read the long way round, as ArduPilot reads it (:attr:`wraps`).

        Returns
        -------
        shapely.Polygon or shapely.MultiPolygon
            Possibly empty (a polygon without area).
        """
        if self.shape == "circle":
            # ArduPilot's own circle: its flat-earth distance, an ellipse in lon/lat
            lon, lat = self.lonlat[0]
            if self.radius_m < LATLON_TO_M * 1e-7:  # within one step of the vehicle's degrees
                return shapely.Polygon()
            # a millimetre and a millionth for the inverse's rounding, on the safe side
            r = (
                self.radius_m * (1 - 1e-6) - 0.001
                if self.inclusion
                else ((self.radius_m * (1 + 1e-6) + 0.001) / math.cos(math.pi / segments))
            )
            rlon, rlat = vehicle_circle_rim(lon, lat, max(r, 0.0), segments)
            disc = shapely.Polygon(np.column_stack([rlon, rlat])[::-1])
            # a circle too small for degrees to tell its vertices apart has no area
            return disc if disc.is_valid and disc.area > 0 else shapely.Polygon()
        if self.wraps:
            return _long_way(self.lonlat)
        # validity is judged in metres, in a frame centred on the polygon
        frame = LocalFrame.around_coords(self.lonlat)
        poly = frame.geom_to_local(shapely.Polygon(self.lonlat))
        if not poly.is_valid:
            poly = shapely.make_valid(poly)
        parts = [
            p
            for p in shapely.get_parts(shapely.get_parts(poly))
            if isinstance(p, shapely.Polygon) and p.area > 0
        ]
        if not parts:
            return shapely.Polygon()
        local = parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)
        return frame.geom_to_wgs84(local)


def _long_way(lonlat):
    """A polygon whose vertices span more than 180° of longitude as ArduPilot reads it: its
    edges straight in lon/lat, never across the antimeridian (the long way round), given as
    its parts west and east of the prime meridian, each narrower than 180°."""
    poly = shapely.make_valid(shapely.Polygon(lonlat))
    halves = [shapely.box(-180.0, -90.0, 0.0, 90.0), shapely.box(0.0, -90.0, 180.0, 90.0)]
    parts = [
        p
        for half in halves
        for p in shapely.get_parts(shapely.intersection(poly, half)).tolist()
        if isinstance(p, shapely.Polygon) and p.area > 0
    ]
    return shapely.MultiPolygon(parts) if parts else shapely.Polygon()


def decode_fence(items, source: str = "the vehicle's fence") -> list:
    """The polygons and circles of a fence item list, checked as ArduPilot checks them.

    Parameters
    ----------
    items : sequence of FenceItem
        In sequence order (anything with ``command``, ``param1``, ``lon``, ``lat``).
    source : str
        What the items are, for the error message.

    Returns
    -------
    list of OnboardFence
        In item order; the return point is left out.

    Raises
    ------
    InputError
        One line naming the item: a command that is not a fence item, a position out of
        range, a circle radius that is not a positive number, a polygon vertex count outside
        3-255, or a polygon whose ``n`` vertices are not ``n`` consecutive items of one
        command each saying ``n``.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> tri = [FenceItem(5002, 3.0, 14.5, 35.9), FenceItem(5002, 3.0, 14.6, 35.9),
    ...        FenceItem(5002, 3.0, 14.5, 36.0)]
    >>> [f.name for f in decode_fence(tri + [FenceItem(5004, 50.0, 14.7, 35.8)])]
    ['onboard exclusion polygon 1 (items 0-2)', 'onboard exclusion circle 1 (item 3)']
    >>> decode_fence(tri[:2])
    Traceback (most recent call last):
    ...
    alphafence.errors.InputError: the vehicle's fence: item 0: a polygon of 3 vertices has only 2 items
    """
    items = list(items)
    for i, item in enumerate(items):  # each item on its own first, then how they group
        command, param1, _, _ = _fields(item, i, source)
        if command in POLYGONS:
            _vertex_count(param1, i, source)
    fences, counts, i = [], {}, 0
    while i < len(items):
        command, param1, lon, lat = _fields(items[i], i, source)
        if command == RETURN_POINT:
            i += 1
            continue
        key = (command in INCLUSIONS, command in POLYGONS)
        counts[key] = number = counts.get(key, 0) + 1
        if command in CIRCLES:
            if not (math.isfinite(param1) and 0 < param1 <= MAX_RADIUS_M):
                raise InputError(source, f"circle radius {param1:g} m", f"item {i}")
            fences.append(OnboardFence(key[0], "circle", number, i, i, ((lon, lat),), param1))
            i += 1
            continue
        n = _vertex_count(param1, i, source)
        if i + n > len(items):
            have = len(items) - i
            raise InputError(
                source, f"a polygon of {n} vertices has only {have} items", f"item {i}"
            )
        vertices = []
        for j in range(i, i + n):
            c, p, x, y = _fields(items[j], j, source) if j > i else (command, param1, lon, lat)
            if c != command or p != param1:
                raise InputError(
                    source,
                    f"a polygon of {n} vertices starting at item {i} is broken by "
                    f"{_describe(c)} saying {p:g}",
                    f"item {j}",
                )
            vertices.append((x, y))
        fences.append(OnboardFence(key[0], "polygon", number, i, i + n - 1, tuple(vertices)))
        i += n
    return fences


def _fields(item, i, source):
    try:
        command, param1 = int(item.command), float(item.param1)
        lon, lat = float(item.lon), float(item.lat)
    except (TypeError, ValueError, OverflowError, AttributeError):
        raise InputError(source, "a field is missing or not a number", f"item {i}") from None
    if command not in POLYGONS + CIRCLES + (RETURN_POINT,):
        raise InputError(source, f"command {command} is not a fence item", f"item {i}")
    if not valid_lonlat(lon, lat):
        raise InputError(source, f"position {lat:.7f}, {lon:.7f} out of range", f"item {i}")
    return command, param1, lon, lat


def _vertex_count(param1, i, source) -> int:
    if not (math.isfinite(param1) and param1 == int(param1)):
        raise InputError(source, f"polygon vertex count {param1:g}", f"item {i}")
    n = int(param1)
    if not 3 <= n <= MAX_POLYGON_VERTICES:
        raise InputError(
            source, f"polygon vertex count {n} (3 to {MAX_POLYGON_VERTICES})", f"item {i}"
        )
    return n


def _describe(command) -> str:
    names = {
        POLYGON_INCLUSION: "an inclusion vertex",
        POLYGON_EXCLUSION: "an exclusion vertex",
        CIRCLE_INCLUSION: "an inclusion circle",
        CIRCLE_EXCLUSION: "an exclusion circle",
        RETURN_POINT: "a return point",
    }
    return names[command]


def breached(fences, lon, lat, union=False) -> bool:
    """Whether a vehicle holding ``fences`` breaches them at ``(lon, lat)``, as ArduPilot's
    ``AC_PolyFence_loader::breached`` decides: inside an exclusion polygon (its integer
    degrees, :func:`~alphafence.geo.vehicle_distance.polygon_outside`) or circle (its
    distance, :func:`~alphafence.geo.vehicle_distance.vehicle_distance_m`); outside an
    inclusion when ``union`` is False (ArduPilot's default: inside every one), outside all of
    them when True (``FENCE_OPTIONS`` bit 1).

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> west = [FenceItem(5001, 4.0, x, y) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    >>> east = [FenceItem(5001, 4.0, x + 2, y) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    >>> fences = decode_fence(west + east)
    >>> breached(fences, 0.5, 0.5), breached(fences, 0.5, 0.5, union=True)
    (True, False)
    >>> breached(fences, 1.5, 0.5, union=True)
    True
    """
    lon, lat = np.asarray([float(lon)]), np.asarray([float(lat)])
    inclusions = outside = 0
    for f in fences:
        if f.shape == "circle":
            d = float(vehicle_distance_m(lon, lat, *f.lonlat[0])[0])
            out = d > f.radius_m if f.inclusion else d >= f.radius_m  # as ArduPilot compares
        else:
            ring = np.asarray(f.lonlat, float)
            out = bool(polygon_outside(lon, lat, ring[:, 0], ring[:, 1])[0])
        if not f.inclusion and not out:
            return True
        if f.inclusion:
            inclusions += 1
            outside += out
    if union:
        return inclusions > 0 and outside == inclusions
    return outside > 0


def path_breaches(items, path) -> list:
    """The vertices of a flight path (home first) where a vehicle holding ``items`` breaches
    them by its own rule (:func:`breached`; several inclusions read as their union, as
    ``upload`` sets ``FENCE_OPTIONS``), by index.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> square = [FenceItem(5001, 4.0, x, y) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    >>> path_breaches(square, shapely.LineString([(0.5, 0.5), (2.0, 0.5), (0.5, 0.6)]))
    [1]
    """
    from alphafence.mavlink.inclusions import needs_union

    fences, union = decode_fence(items), needs_union(items)
    pts = shapely.get_coordinates(path)
    return [k for k, (lon, lat) in enumerate(pts) if breached(fences, lon, lat, union)]
