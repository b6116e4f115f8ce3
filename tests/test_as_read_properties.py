"""Fences hold as they are read, property-tested on long zones: every fence the build writes
(in memory, GeoJSON, GeoParquet, QGroundControl .plan, ArduPilot .waypoints) and every
onboard fence contains its zone plus margin, or for keep-in lies inside the zone less the
margin, **as ArduPilot reads it**: polygons by its integer ``Polygon_outside`` on the lat/lng
of the vertices (straight lon/lat edges), circles by its own flat-earth distance, the zone's
edges straight lon/lat lines as GeoJSON means them, distances geodesic on WGS84
(:mod:`tests.ardupilot_model`, which shares no code with the build's frames).

Zones are 10 to 1,000 km long: strips along parallels, diagonals, zigzags (meanders) and
overlapping pairs, in both hemispheres up to 80 degrees. Every example is checked (the
statistics' events count them by shape)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import shapely
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from alphafence.build.fences import METHODS
from alphafence.build.outputs import render
from alphafence.build.pipeline import BuildOptions, build_fences
from alphafence.formats.atomic import write_all
from alphafence.formats.fence_geojson import fences_geojson
from alphafence.formats.fence_read import read_fence_file
from alphafence.formats.fence_stream import open_writers
from alphafence.formats.qgc_plan import group_polygons, read_plan_fence
from alphafence.formats.qgc_wpl import read_waypoints_fence
from alphafence.formats.rules import parse_rules
from alphafence.mavlink.items import CIRCLE_EXCLUSION, POLYGON_EXCLUSION, POLYGON_INCLUSION
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences

from .ardupilot_model import GEOD, clearance, excursion_m, location_distance_m, zone_features

KM = 1000.0


def _rules(kind, margin):
    return parse_rules(
        {
            "defaults": {"point_radius_m": 15.0, "line_width_m": 6.0},
            "rule": [
                {"category": "zone", "kind": kind, "tags": {"restricted": "*"}, "margin_m": margin}
            ],
        }
    )


def _walk(lon, lat, azimuth, metres):
    """The point ``metres`` from ``(lon, lat)`` along the geodesic at ``azimuth``."""
    out = GEOD.fwd(lon, lat, azimuth, metres)
    return float(out[0]), float(out[1])


def _strip(lon, lat, azimuth, length, width, bends=0, seed=0):
    """A strip ``length`` long and ``width`` wide from ``(lon, lat)`` along ``azimuth``
    (bending ``bends`` times by up to 40 degrees), drawn with straight lon/lat edges between
    its corners: a long zone as a national file draws one."""
    rng = np.random.default_rng(seed)
    legs = bends + 1
    pts, az = [(lon, lat)], azimuth
    for _ in range(legs):
        pts.append(_walk(*pts[-1], az, length / legs))
        az += float(rng.uniform(-40, 40))
    left, right = [], []
    for i, (x, y) in enumerate(pts):
        a = GEOD.inv(*pts[max(i - 1, 0)], *pts[min(i + 1, len(pts) - 1)])[0]
        left.append(_walk(x, y, a - 90.0, width / 2))
        right.append(_walk(x, y, a + 90.0, width / 2))
    ring = left + right[::-1]
    poly = shapely.Polygon(ring)
    return poly if poly.is_valid else shapely.make_valid(poly).convex_hull


def _split_at_180(zone):
    """A zone reaching past 180° of longitude as an RFC 7946 file holds it: a part on each
    side of the antimeridian."""

    def east(c):
        return np.column_stack([np.where(c[:, 0] < 0.0, c[:, 0] + 360.0, c[:, 0]), c[:, 1]])

    whole = shapely.transform(zone, east)
    a = shapely.intersection(whole, shapely.box(0.0, -90.0, 180.0, 90.0))
    b = shapely.intersection(whole, shapely.box(180.0, -90.0, 360.0, 90.0))
    b = shapely.transform(b, lambda c: c - np.array([360.0, 0.0]))
    parts = [p for g in (a, b) for p in shapely.get_parts(g) if p.geom_type == "Polygon"]
    return shapely.MultiPolygon(parts) if len(parts) > 1 else parts[0]


@st.composite
def long_zones(draw):
    shape = draw(
        st.sampled_from(["parallel", "diagonal", "meander", "overlapping", "antimeridian"])
    )
    lat = draw(st.floats(-80.0, 80.0))
    lon = draw(st.floats(-170.0, 170.0))
    if shape == "antimeridian":
        length = draw(st.sampled_from([10, 50, 200])) * KM
        start = _walk(180.0, lat, 270.0, length / 2)
        az = draw(st.sampled_from([90.0, 70.0, 110.0]))
        zone = _strip(*start, az, length, draw(st.floats(0.5, 20.0)) * KM)
        if zone.bounds[3] <= 84.0 and zone.bounds[1] >= -84.0:
            return shape, [_split_at_180(zone)]
    length = draw(st.sampled_from([10, 50, 200, 1000])) * KM
    width = draw(st.floats(0.5, 20.0)) * KM
    seed = draw(st.integers(0, 2**16))
    if shape == "parallel":
        az = draw(st.sampled_from([90.0, 270.0]))
        zones = [_strip(lon, lat, az, length, width)]
    elif shape == "diagonal":
        zones = [_strip(lon, lat, draw(st.floats(10.0, 80.0)), length, width)]
    elif shape == "meander":
        zones = [_strip(lon, lat, 90.0, length, width, bends=draw(st.integers(2, 5)), seed=seed)]
    else:
        a = _strip(lon, lat, 90.0, length, width)
        mid = shapely.centroid(a)
        b = _strip(mid.x, mid.y - 0.2, draw(st.floats(20.0, 70.0)), length / 2, width)
        zones = [a, b]
    # beyond 80 degrees or across the antimeridian the strips above are not what this tests
    zones = [z for z in zones if z.bounds[3] <= 84.0 and z.bounds[1] >= -84.0]
    zones = [z for z in zones if z.bounds[2] - z.bounds[0] < 180.0]
    return shape, zones or [_strip(lon, 0.0, 90.0, length, width)]


def _features(zones, rules):
    return zone_features(zones, rules, "long.geojson")


def _rings(geom):
    return [np.asarray(p.exterior.coords)[:-1] for p in shapely.get_parts(geom)]


def _members(fence_sources, zones):
    return [zones[int(s.rsplit("/", 1)[-1])] for s in fence_sources]


def _holds(zone, rings, circles, margin, what):
    """ArduPilot's reading of ``rings`` (polygons) and ``circles`` ((lon, lat, r)) holds the
    zone plus margin."""
    if circles:
        az = np.arange(0.0, 360.0, 0.5)
        for lon, lat, r in circles:
            # every sample of the zone's boundary, pushed out by the margin every way
            from .ardupilot_model import boundary_samples

            zl, zt = boundary_samples(zone, max(margin / 4, 5.0))
            n = len(zl)
            plon, plat, _ = GEOD.fwd(np.repeat(zl, az.size), np.repeat(zt, az.size),
                                     np.tile(az, n), np.full(n * az.size, margin))  # fmt: skip
            d = location_distance_m(plat, plon, lat, lon)
            assert d.max() < r, f"{what}: the zone reaches {d.max() - r:.2f} m out of the circle"
        return
    out = excursion_m(zone, rings, margin, spacing_m=max(margin / 4, 50.0))
    assert out <= 0.01, f"{what}: the zone plus {margin} m reaches {out:.2f} m out of the fence"


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    zone=long_zones(),
    method=st.sampled_from(METHODS),
    margin=st.sampled_from([0.0, 10.0, 100.0]),
    max_vertices=st.sampled_from([8, 32]),
)
def test_keep_out_fences_hold_as_ardupilot_reads_them_in_every_format(
    zone, method, margin, max_vertices
):
    shape, zones = zone
    rules = _rules("keep_out", margin)
    features = _features(zones, rules)
    opts = BuildOptions(method=method, max_vertices=max_vertices, warn_distance_m=30.0)
    result = build_fences(features, rules, opts)
    event(f"checked: {shape}")
    with tempfile.TemporaryDirectory() as tmp:
        names = ("f.geojson", "f.plan", "f.waypoints")
        paths = [str(Path(tmp) / n) for n in names]
        write_all(render(result.fences, {}, *paths))
        doc = json.loads(Path(paths[0]).read_text())
        geojson = {
            (f["properties"]["site_id"], f["properties"]["kind"]): shapely.geometry.shape(
                f["geometry"]
            )
            for f in doc["features"]
        }
        plan_items = read_plan_fence(paths[1])
        wpl_items = read_waypoints_fence(paths[2])
        parquet = _parquet_fences(result.fences, Path(tmp) / "f.parquet")
    for fence in result.fences:
        members = _members(fence.sources, zones)
        m = fence.margin_m
        circles = [fence.circle_wgs84] if fence.circle is not None else []
        for zone_k in members:
            # the in-memory fence and GeoJSON: polygons (circles as their polygons)
            _holds(zone_k, _rings(fence.geometry), [], m, f"{method} {fence.kind} fence")
            _holds(zone_k, _rings(geojson[(fence.site_id, fence.kind)]), [], m, "GeoJSON")
            if parquet is not None:
                _holds(zone_k, _rings(parquet[(fence.site_id, fence.kind)]), [], m, "GeoParquet")
    for items, what in ((plan_items, ".plan"), (wpl_items, ".waypoints")):
        polygons, circles = group_polygons(items)
        rings = [np.asarray(p) for cmd, p in polygons if cmd == POLYGON_EXCLUSION]
        discs = [(c.lon, c.lat, c.param1) for c in circles if c.command == CIRCLE_EXCLUSION]
        for fence in (f for f in result.fences if f.kind == "keep_out"):
            for zone_k in _members(fence.sources, zones):
                if fence.circle is not None:
                    mine = [d for d in discs if abs(d[0] - fence.circle_wgs84[0]) < 1e-6]
                    _holds(zone_k, [], mine[:1], fence.margin_m, what)
                else:
                    _holds(zone_k, rings, [], fence.margin_m, what)


def _parquet_fences(fences, path):
    """The fences written as GeoParquet (the build's writer) and read back, by site and
    kind; None without pyarrow."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return None
    features = fences_geojson(fences, {})["features"]
    with open_writers([str(path)], {}) as writers:
        writers.write([encode(features) for encode in writers.encoders()])
    return {(r.site_id, r.kind): r.geometry for r in read_fence_file(str(path))}


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(zone=long_zones(), margin=st.sampled_from([0.0, 100.0]))
def test_keep_in_fences_lie_inside_their_zone_less_margin_as_read(zone, margin):
    shape, zones = zone
    zones = zones[:1]
    rules = _rules("keep_in", margin)
    features = _features(zones, rules)
    try:
        result = build_fences(features, rules, BuildOptions(method="alpha", max_vertices=32))
    except ValueError:  # a zone narrower than twice its margin has no keep-in fence
        event("vanishes inside its margin")
        return
    event(f"checked: {shape}")
    for fence in result.fences:
        # the fence's boundary, read in lon/lat, lies inside the zone (ArduPilot's reading of
        # the zone's vertices) and at least the margin from its boundary
        outside, dist, _, _ = clearance(
            fence.geometry, _rings(zones[0]), spacing_m=max(margin / 4, 50.0), margin_m=margin
        )
        assert outside == 0, f"{outside} samples of the keep-in fence lie outside its zone"
        assert dist >= margin - 0.01, f"the keep-in fence comes {dist:.2f} m from its zone"


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(zone=long_zones(), profile=st.sampled_from(["copter", "sd-fence"]))
def test_onboard_fences_contain_the_fences_they_stand_for_as_read(zone, profile):
    shape, zones = zone
    rules = _rules("keep_out", 10.0)
    result = build_fences(_features(zones, rules), rules, BuildOptions(method="alpha"))
    fences = [f for f in result.fences if f.kind == "keep_out"]
    records = read_back(fences)
    area = shapely.box(*shapely.union_all([r.geometry for r in records]).bounds)
    try:
        onboard = compile_fences(records, area, PROFILES[profile])
    except Exception as err:  # noqa: BLE001 - a budget too small is a refusal, said as such
        assert "fit" in str(err)
        event("does not fit")
        return
    event(f"checked: {shape}")
    polygons, circles = group_polygons(onboard.items)
    rings = [np.asarray(p) for cmd, p in polygons if cmd == POLYGON_EXCLUSION]
    discs = [(c.lon, c.lat, c.param1) for c in circles if c.command == CIRCLE_EXCLUSION]
    assert not [p for cmd, p in polygons if cmd == POLYGON_INCLUSION]
    for rec in records:
        # every fence stands inside some onboard exclusion as ArduPilot reads it
        outside = clearance(rec.geometry, rings, spacing_m=50.0)[0]
        in_disc = not discs or _in_circles(rec.geometry, discs)
        assert outside == 0 or in_disc, f"{outside} samples of {rec.site_id} stand outside"


def _in_circles(geom, discs):
    from .ardupilot_model import boundary_samples

    lon, lat = boundary_samples(geom, 50.0)
    inside = np.zeros(lon.shape, bool)
    for clon, clat, r in discs:
        inside |= location_distance_m(lat, lon, clat, clon) < r
    return bool(inside.all())


def read_back(fences):
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "f.geojson")
        write_all(render(fences, {}, path))
        return read_fence_file(path)


def test_the_check_sees_what_a_metric_frame_hides():
    """The check sees what it must. A round zone 50 km across at 64°N, fenced by a square drawn
    50 m around it in a metric frame (4 corners), holds in the frame; read in lon/lat as
    ArduPilot reads it, the square's north edge is a parallel, about 100 m south of the
    straight line in the middle: it cuts about 50 m into the zone. Drawn with 200 vertices a side, the
    square holds it, 50 m clear."""
    from alphafence.geo.frame import LocalFrame

    az = np.arange(0.0, 360.0, 1.0)
    lon, lat, _ = GEOD.fwd(np.full(az.size, 10.5), np.full(az.size, 64.0), az,
                           np.full(az.size, 25_000.0))  # fmt: skip
    zone = shapely.Polygon(np.column_stack([lon, lat]))
    frame = LocalFrame(10.5, 64.0)
    x0, y0, x1, y1 = frame.read_geom(zone).bounds
    square = shapely.box(x0 - 50.0, y0 - 50.0, x1 + 50.0, y1 + 50.0)
    assert square.covers(shapely.buffer(frame.read_geom(zone), 49.9))  # it holds in the frame
    corners = np.asarray(frame.geom_to_wgs84(square).exterior.coords)[:-1]
    out = excursion_m(zone, [corners], 50.0, spacing_m=20.0)
    assert 90.0 < out < 110.0, out  # 50 m of margin, and about 50 m into the zone
    dense = np.asarray(frame.geom_to_wgs84(shapely.segmentize(square, 300.0)).exterior.coords)
    assert excursion_m(zone, [dense[:-1]], 50.0, spacing_m=20.0) < 0.01
