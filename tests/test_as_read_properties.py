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
import pytest
import shapely
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.fencefiles.atomic import write_all
from alphafence.fencefiles.fence_geojson import fences_geojson
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.fencefiles.fence_stream import open_writers
from alphafence.fencefiles.qgc_plan import group_polygons, read_plan_fence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
from alphafence.fencing.fences import METHODS
from alphafence.fencing.outputs import render
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.mavlink.items import CIRCLE_EXCLUSION, POLYGON_EXCLUSION, POLYGON_INCLUSION
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences
from alphafence.zones.rules import parse_rules

from .ardupilot_model import (
    CHUNK,
    GEOD,
    boundary_samples,
    breached,
    circle_rim,
    clearance,
    covers_as_read,
    excursion_m,
    location_distance_m,
    polygon_outside,
    spacing_for,
)
from .conftest import checked
from .zone_samples import zone_features

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
def long_zones(draw, size_km):
    """A zone ``size_km`` long (a strip along a parallel, a diagonal, a meander, an
    overlapping pair, or one across the antimeridian) anywhere up to 80 degrees."""
    shape = draw(
        st.sampled_from(["parallel", "diagonal", "meander", "overlapping", "antimeridian"])
    )
    lat = draw(st.floats(-80.0, 80.0))
    lon = draw(st.floats(-170.0, 170.0))
    length = size_km * KM
    width = draw(st.floats(0.5, 20.0)) * KM
    if shape == "antimeridian":
        start = _walk(180.0, lat, 270.0, length / 2)
        az = draw(st.sampled_from([90.0, 70.0, 110.0]))
        zone = _strip(*start, az, length, width)
        if zone.bounds[3] <= 84.0 and zone.bounds[1] >= -84.0 and size_km <= 200:
            return shape, [_split_at_180(zone)]
        shape = "parallel"
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
    zone plus margin: the polygons cover the zone exactly (lon/lat lines, 1e-7 degrees), and
    no zone sample lies nearer than the margin to their boundary (samples
    ``spacing_for(margin)`` apart: between them the distance dips by at most a tenth of the
    margin); a circle holds every sample pushed out by the margin, measured as ArduPilot
    measures."""
    if circles:
        zl, zt = boundary_samples(zone, spacing_for(margin))
        for lon, lat, r in circles:
            worst = -np.inf
            for start in range(0, len(zl), CHUNK):  # bounded memory for any zone
                pl, pt = zl[start : start + CHUNK], zt[start : start + CHUNK]
                az = GEOD.inv(np.full(pl.size, lon), np.full(pl.size, lat), pl, pt)[0]
                for turn in (-10.0, -5.0, 0.0, 5.0, 10.0):  # outward, and either side of it
                    ql, qt, _ = GEOD.fwd(pl, pt, az + turn, np.full(pl.size, margin))
                    worst = max(worst, float(location_distance_m(qt, ql, lat, lon).max()))
            assert worst < r, f"{what}: the zone reaches {worst - r:.2f} m out of the circle"
        return
    assert covers_as_read(rings, zone), f"{what}: the zone is not inside the fence as read"
    if margin > 0:
        out = excursion_m(zone, rings, margin)
        assert out <= 0.01, f"{what}: the zone plus {margin} m reaches {out:.2f} m out of the fence"


def _e7(items):
    return [(i.command, i.param1, round(i.lon * 1e7), round(i.lat * 1e7)) for i in items]


def _keep_out_outputs(result, zones):
    """Every output of a keep-out build checked as read, and every zone fenced."""
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
    keep_out = [f for f in result.fences if f.kind == "keep_out"]
    fenced = {int(s.rsplit("/", 1)[-1]) for f in keep_out for s in f.sources}
    assert fenced == set(range(len(zones))), (
        f"zones without a fence: {set(range(len(zones))) - fenced}"
    )
    # the files carry the in-memory fence's vertices to 1e-8 degrees (a millimetre): each
    # covers its zones exactly as read; the margin, measured on the fence, holds for them to
    # the millimetre
    for fence in keep_out:
        key = (fence.site_id, fence.kind)
        for copy in (geojson[key], *([parquet[key]] if parquet is not None else [])):
            assert shapely.hausdorff_distance(copy, fence.geometry) < 1e-8
            for zone_k in _members(fence.sources, zones):
                assert covers_as_read(_rings(copy), zone_k), f"{fence.site_id}: a file's copy"
    for fence in keep_out:
        for zone_k in _members(fence.sources, zones):
            _holds(zone_k, _rings(fence.geometry), [], fence.margin_m, f"{fence.site_id} in memory")
    for items, what in ((plan_items, ".plan"), (wpl_items, ".waypoints")):
        polygons, circles = group_polygons(items)
        rings = [np.asarray(p) for cmd, p in polygons if cmd == POLYGON_EXCLUSION]
        discs = [(c.lon, c.lat, c.param1) for c in circles if c.command == CIRCLE_EXCLUSION]
        for fence in keep_out:
            for zone_k in _members(fence.sources, zones):
                if fence.circle is not None:
                    mine = [d for d in discs if abs(d[0] - fence.circle_wgs84[0]) < 1e-6]
                    _holds(zone_k, [], mine[:1], fence.margin_m, f"{what} circle")
                else:
                    _holds(zone_k, rings, [], fence.margin_m, what)


SIZES = [10, 50, 200, 1000]  # km: every method meets every size class in every run


@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), margin=st.sampled_from([0.0, 10.0, 100.0]),
       max_vertices=st.sampled_from([8, 32]))  # fmt: skip
@pytest.mark.parametrize("size_km", SIZES)
@pytest.mark.parametrize("method", METHODS)
def test_keep_out_fences_hold_as_ardupilot_reads_them_in_every_format(
    method, size_km, data, margin, max_vertices
):
    shape, zones = data.draw(long_zones(size_km))
    rules = _rules("keep_out", margin)
    opts = BuildOptions(method=method, max_vertices=max_vertices, warn_distance_m=30.0)
    result = build_fences(_features(zones, rules), rules, opts)
    event(f"checked: {method} {size_km} km {shape} margin {margin:g}")
    _keep_out_outputs(result, zones)
    checked("keep-out", method, size_km)


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


def _inside_less_margin(shape, zone, margin, what):
    """A keep-in shape (lon/lat polygon, as read) lies inside its zone, at least the margin
    (less a tenth of it, between samples) from the zone's boundary."""
    assert covers_as_read(_rings(zone), shape), f"{what}: it reaches out of its zone"
    outside, dist, _, _ = clearance(shape, _rings(zone), margin_m=margin)
    assert outside == 0, f"{what}: {outside} samples lie outside its zone"
    assert dist >= margin - 0.01, f"{what}: it comes {dist:.2f} m from its zone"


def _keep_in_outputs(result, zone, margin):
    """Every output of a one-zone keep-in build, read as the vehicle reads it: each
    inclusion inside the zone less the margin, and the inclusions one area (more than one
    is marked as needing FENCE_OPTIONS' union, which the upload sets)."""
    fences = [f for f in result.fences if f.kind == "keep_in"]
    assert fences, "the zone has no keep-in fence"
    with tempfile.TemporaryDirectory() as tmp:
        paths = [str(Path(tmp) / n) for n in ("f.geojson", "f.plan", "f.waypoints")]
        write_all(render(result.fences, {}, *paths))
        records = read_fence_file(paths[0])
        plan = json.loads(Path(paths[1]).read_text())
        items = read_plan_fence(paths[1])
        wpl = read_waypoints_fence(paths[2])
        assert np.abs(np.subtract(_e7(items), _e7(wpl))).max(initial=0) <= 1  # 8 decimals
    for rec in records:
        _inside_less_margin(rec.geometry, zone, margin, f"GeoJSON {rec.site_id}")
    polygons, circles = group_polygons(items)
    inclusions = [p for cmd, p in polygons if cmd == POLYGON_INCLUSION]
    for ring in inclusions:
        _inside_less_margin(shapely.Polygon(ring), zone, margin, ".plan inclusion polygon")
    for c in circles:
        rim = np.column_stack(circle_rim(c.lon, c.lat, c.param1))
        where = zone
        if np.abs(rim[:, 0]).max() > 180.0:
            # ArduPilot's distance wraps at ±180°: rim and zone are turned half a world round
            # (a turn in longitude changes no distance and no lon/lat line) and compared there
            turn = lambda xy: np.column_stack([xy[:, 0] % 360.0 - 180.0, xy[:, 1]])  # noqa: E731
            rim = turn(rim)
            where = shapely.union_all(shapely.transform(shapely.get_parts(zone), turn))
        _inside_less_margin(shapely.Polygon(rim), where, margin, ".plan inclusion circle")
    union = "alphafence" in plan["geoFence"]  # the upload sets FENCE_OPTIONS' union then
    assert (len(inclusions) + len(circles) > 1) == union
    # inside every part of the fence is no breach by the vehicle's own rule, and outside the
    # zone is one: the keep-in keeps the vehicle in
    for rec in records:
        for part in shapely.get_parts(rec.geometry):
            p = part.representative_point()
            assert not breached(items, [p.x], [p.y], union)[0], "inside the keep-in: a breach"
    lon, lat = _around(zone)
    assert lon.size and breached(items, lon, lat, union).all(), "outside the zone: no breach"


def _around(zone, n=24):
    """Positions on a grid round the zone's bounds, outside the zone (a tenth of its size
    beyond its bounds on every side, and the grid's points inside the bounds the zone does
    not cover)."""
    x0, y0, x1, y1 = zone.bounds
    dx, dy = (x1 - x0) * 0.1 + 1e-3, (y1 - y0) * 0.1 + 1e-3
    lon, lat = np.meshgrid(np.linspace(x0 - dx, x1 + dx, n), np.linspace(y0 - dy, y1 + dy, n))
    lon, lat = lon.ravel(), np.clip(lat.ravel(), -89.0, 89.0)
    keep = (np.abs(lon) < 180.0) & ~shapely.intersects_xy(zone, lon, lat)
    return lon[keep], lat[keep]


def _vanishes(zone, margin):
    """Whether the zone has no point more than its margin (and a tenth, and a metre) from its
    boundary: measured in an azimuthal equidistant frame of pyproj's at the zone's centre."""
    from pyproj import Transformer

    c = zone.centroid
    to_m = Transformer.from_crs(
        "EPSG:4326", f"+proj=aeqd +lat_0={c.y} +lon_0={c.x} +ellps=WGS84", always_xy=True
    )
    local = shapely.transform(zone, lambda xy: np.column_stack(to_m.transform(*xy.T)))
    return bool(shapely.buffer(local, -(margin * 1.1 + 1.0)).is_empty)


@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), margin=st.sampled_from([0.0, 10.0, 100.0]))
@pytest.mark.parametrize("size_km", SIZES)
@pytest.mark.parametrize("method", METHODS)
def test_keep_in_fences_lie_inside_their_zone_less_margin_as_read(method, size_km, data, margin):
    shape, zones = data.draw(long_zones(size_km))
    rules = _rules("keep_in", margin)
    try:
        result = build_fences(_features(zones[:1], rules), rules,
                              BuildOptions(method=method, max_vertices=32))  # fmt: skip
    except ValueError:  # a zone narrower than twice its margin has no keep-in fence
        assert _vanishes(zones[0], margin), f"{method}: refused a zone wider than its margin"
        event("vanishes inside its margin")
        return
    event(f"checked: {method} {size_km} km {shape} margin {margin:g}")
    _keep_in_outputs(result, zones[0], margin)
    checked("keep-in", method, size_km)


@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
@pytest.mark.parametrize("size_km", SIZES)
@pytest.mark.parametrize("profile", ["copter", "sd-fence"])
def test_onboard_fences_contain_the_fences_they_stand_for_as_read(profile, size_km, data):
    shape, zones = data.draw(long_zones(size_km))
    rules = _rules("keep_out", 10.0)
    result = build_fences(_features(zones, rules), rules, BuildOptions(method="alpha"))
    records = read_back([f for f in result.fences if f.kind == "keep_out"])
    area = shapely.box(*shapely.union_all([r.geometry for r in records]).bounds)
    try:
        onboard = compile_fences(records, area, PROFILES[profile])
    except InputError as err:  # a refusal writes nothing: said as such, counted
        event("refused: does not fit" if "fit" in str(err) else "refused: not held as read")
        return
    event(f"checked: {profile} {size_km} km {shape}")
    _onboard_holds(records, onboard.items)
    checked("onboard", profile, size_km)


def _onboard_holds(records, items):
    """Every fence lies inside the onboard exclusions as ArduPilot reads them: each sample of
    its boundary (and its interior, exactly, for polygons alone) is excluded by a polygon
    or a circle."""
    polygons, circles = group_polygons(items)
    rings = [np.asarray(p) for cmd, p in polygons if cmd == POLYGON_EXCLUSION]
    discs = [(c.lon, c.lat, c.param1) for c in circles if c.command == CIRCLE_EXCLUSION]
    assert not [p for cmd, p in polygons if cmd == POLYGON_INCLUSION]
    for rec in records:
        lon, lat = boundary_samples(rec.geometry, 50.0)
        inside = np.zeros(lon.shape, bool)
        for ring in rings:
            inside |= ~polygon_outside(lat, lon, ring[:, 1], ring[:, 0])
        for clon, clat, r in discs:
            inside |= location_distance_m(lat, lon, clat, clon) < r
        assert inside.all(), f"{(~inside).sum()} samples of {rec.site_id} stand outside"
        if not discs:
            assert covers_as_read(rings, rec.geometry), f"{rec.site_id} is not covered"


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


def test_the_keep_in_checks_fail_on_a_refusal_or_a_fence_that_keeps_nothing_in():
    # broken on purpose: a build that refuses a 1 km wide zone with a 100 m margin is caught
    # (only a zone narrower than twice its margin may be refused), and so is a fence read
    # with no inclusion (nothing outside the zone is a breach)
    wide = _strip(14.5, 35.9, 90.0, 10 * KM, 1 * KM)
    narrow = _strip(14.5, 35.9, 90.0, 10 * KM, 0.15 * KM)
    assert not _vanishes(wide, 100.0) and _vanishes(narrow, 100.0)
    rules = _rules("keep_in", 100.0)
    result = build_fences(_features([wide], rules), rules, BuildOptions(method="alpha"))
    _keep_in_outputs(result, wide, 100.0)
    lon, lat = _around(wide)
    assert lon.size > 100 and not breached([], lon, lat, False).any()
