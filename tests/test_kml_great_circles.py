"""KML polygons with long edges, which Google Earth draws along geodesics and the kit reads as
straight lon/lat lines: a keep-out zone read from KML holds both readings, a keep-in zone
only what both readings share, and a short-edged polygon comes back as written.

Everything expected is computed here, independently of the kit: the rings parsed with
xml.etree, each edge's geodesic from pyproj's ``Geod.npts`` every 100 m, distances in
metres in an azimuthal equidistant projection built with pyproj for each zone."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pyproj
import pytest
import shapely

from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.zones.database import read_database

SAMPLE = Path(__file__).parent / "data" / "kml" / "great-circle-edges.kml"
K = "{http://www.opengis.net/kml/2.2}"
GEOD = pyproj.Geod(ellps="WGS84")
STEP_M = 100.0  # the test's own geodesic points: a 100 m lon/lat chord bows under a millimetre
FOLLOW_M = 0.05  # the kit follows each reading to this
LONG = ("Range strip", "Strait across the date line", "Range block")


def rings():
    """Independent parse: placemark name -> its outer ring [(lon, lat)], as written."""
    out = {}
    for pm in ET.parse(SAMPLE).getroot().iter(f"{K}Placemark"):
        text = pm.find(f".//{K}coordinates").text
        out[pm.findtext(f"{K}name")] = [tuple(map(float, t.split(",")[:2])) for t in text.split()]
    return out


def unwrapped(lon):
    """Longitudes the short way across the antimeridian (negative ones east by 360 when the
    coordinates span more than 180 degrees)."""
    lon = np.asarray(lon, float)
    return np.where(lon < 0, lon + 360.0, lon) if np.ptp(lon) > 180.0 else lon


def lonlat_polygon(ring):
    """The ring with straight lon/lat edges, every edge cut into 1,000 pieces (in lon/lat)."""
    xy = np.array(ring, float)
    xy[:, 0] = unwrapped(xy[:, 0])
    t = np.arange(1000) / 1000.0
    pts = [a + (b - a) * s for a, b in zip(xy[:-1], xy[1:]) for s in t]
    return np.array(pts)


def geodesic_polygon(ring):
    """The ring with each edge along its geodesic: pyproj points every STEP_M metres."""
    pts = []
    for (lon1, lat1), (lon2, lat2) in zip(ring[:-1], ring[1:]):
        length = GEOD.inv(lon1, lat1, lon2, lat2)[2]
        n = max(int(math.ceil(length / STEP_M)) - 1, 0)
        pts.append((lon1, lat1))
        pts.extend(GEOD.npts(lon1, lat1, lon2, lat2, n))
    pts = np.array(pts, float)
    pts[:, 0] = unwrapped(pts[:, 0])
    return pts


class Metres:
    """Positions in metres in an azimuthal equidistant projection about the centre of
    (lon, lat) points."""

    def __init__(self, points):
        lon = unwrapped([p[0] for p in points])
        lat = [p[1] for p in points]
        lon0 = (lon.min() + lon.max()) / 2.0
        lon0 = lon0 - 360.0 if lon0 > 180.0 else lon0
        self.proj = pyproj.Proj(proj="aeqd", lon_0=lon0, lat_0=(min(lat) + max(lat)) / 2.0)

    def points(self, lonlat):
        x, y = self.proj(np.asarray(lonlat)[:, 0], np.asarray(lonlat)[:, 1])
        return np.column_stack([x, y])

    def polygon(self, lonlat):
        """The polygon of (lon, lat) points, their projections joined by straight lines."""
        return shapely.Polygon(self.points(lonlat))

    def zone(self, geom):
        """A zone as read (lon/lat edges, the short way; outer rings), its edges cut into
        pieces of at most 0.001 degrees first."""
        out = []
        for poly in shapely.get_parts(geom):
            coords = np.array(poly.exterior.coords)
            coords[:, 0] = unwrapped(coords[:, 0])
            dense = shapely.segmentize(shapely.Polygon(coords), 0.001)
            out.append(shapely.Polygon(self.points(np.array(dense.exterior.coords))))
        return shapely.union_all(out)


def outside_m(points, area):
    """How far (metres) the farthest of ``points`` lies outside ``area`` (0 inside)."""
    return float(shapely.distance(area, shapely.points(np.asarray(points))).max())


def edge_points(area):
    return shapely.get_coordinates(area.boundary)


def assert_held_both_ways(geometry, rings):
    """A keep-out zone read from KML holds its polygons (outer ``rings`` of (lon, lat),
    united) with edges straight in lon/lat and with edges along geodesics, each to within
    what the kit follows them to, and no more than both. Returns how far apart (metres) the
    two readings lie at most."""
    m = Metres([p for ring in rings for p in ring])
    lonlat = shapely.union_all([m.polygon(lonlat_polygon(r)) for r in rings])
    geodesic = shapely.union_all([m.polygon(geodesic_polygon(r)) for r in rings])
    read = m.zone(geometry)
    assert outside_m(edge_points(lonlat), read) < 0.001
    assert outside_m(edge_points(geodesic), read) < FOLLOW_M
    both = shapely.union(lonlat, geodesic)
    assert abs(read.area - both.area) < FOLLOW_M * both.length
    return outside_m(edge_points(geodesic), lonlat)


@pytest.fixture(scope="module")
def zones(rules):
    """Each reader's zones by placemark name: the database (rules) and the fence reader."""
    db = {f.name: f for f in read_database([SAMPLE], rules).features}
    fences = {f.name: f for f in read_fence_file(SAMPLE)}
    return {"database": db, "fences": fences}


@pytest.mark.parametrize("reader", ["database", "fences"])
@pytest.mark.parametrize("name", LONG[:2])
def test_a_long_keep_out_holds_both_readings(zones, reader, name):
    zone = zones[reader][name]
    assert zone.kind == "keep_out"
    # the sample means something: its two readings lie over 50 m apart
    assert assert_held_both_ways(zone.geometry, [rings()[name]]) > 50.0
    coords = shapely.get_coordinates(zone.geometry)
    assert (np.abs(coords[:, 0]) <= 180.0).all()


@pytest.mark.parametrize("reader", ["database", "fences"])
def test_a_long_keep_in_is_what_both_readings_share(zones, reader):
    ring = rings()["Range block"]
    zone = zones[reader]["Range block"]
    assert zone.kind == "keep_in"
    m = Metres(ring)
    lonlat, geodesic = m.polygon(lonlat_polygon(ring)), m.polygon(geodesic_polygon(ring))
    assert lonlat.symmetric_difference(geodesic).area > 1e6  # km² apart
    read = m.zone(zone.geometry)
    edge = np.array(read.exterior.coords)
    assert outside_m(edge, lonlat) < 0.001
    assert outside_m(edge, geodesic) < FOLLOW_M
    shared = shapely.intersection(lonlat, geodesic)
    assert abs(read.area - shared.area) < FOLLOW_M * shared.length


@pytest.mark.parametrize("reader", ["database", "fences"])
def test_a_short_edged_polygon_comes_back_as_written(zones, reader):
    ring = rings()["Mast"]
    zone = zones[reader]["Mast"]
    assert zone.kind == "keep_out"
    assert list(zone.geometry.exterior.coords) == ring
