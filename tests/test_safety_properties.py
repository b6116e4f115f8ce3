"""Safety invariant, property-tested: every keep-out (and warning) fence contains its site's
restricted area buffered by its margin, for every method, in every output format (the
in-memory fence, GeoJSON, QGroundControl .plan, ArduPilot waypoints), after simplification.
Sites are random and degenerate: collinear points, duplicates, < 3 points, slivers,
point-only, multi-part, near the antimeridian and at high latitude."""

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from pyproj import Geod

from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import group_polygons, read_plan_fence
from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
from alphafence.fencing.fences import METHODS
from alphafence.fencing.outputs import render
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_INCLUSION
from alphafence.mavlink.storage import PROFILES, storage_bytes
from alphafence.onboard.compile import compile_fences
from alphafence.onboard.corridor import flight_path
from alphafence.zones.geojson import read_geojson_doc
from alphafence.zones.rules import parse_rules

from . import px4_model
from .ardupilot_model import circle_inradius_m
from .helpers import VerifyFrame, geojson_fences, missing_area, restricted_in
from .test_compile import contained, fence_sets, onboard_geometry, validate_like_ardupilot

GEOD = Geod(ellps="WGS84")
RULES_DOC = {
    "defaults": {"point_radius_m": 15.0, "line_width_m": 6.0},
    "rule": [
        {"category": "test", "kind": "keep_out", "tags": {"restricted": "*"}, "margin_m": 0.0}
    ],
}

coord = st.floats(-1500, 1500, allow_nan=False)
lat0 = st.one_of(st.floats(-85, 85), st.floats(80, 89.5), st.floats(-89.5, -80))
lon0 = st.one_of(st.floats(-180, 180), st.floats(179.95, 180), st.floats(-180, -179.95))


@st.composite
def shapes(draw):
    kind = draw(st.sampled_from(["star", "rect", "sliver", "point", "line", "collinear", "few"]))
    cx, cy = draw(coord), draw(coord)
    if kind == "star":
        n = draw(st.integers(3, 24))
        radii = draw(st.lists(st.floats(1, 300), min_size=n, max_size=n))
        ang = np.sort(
            np.asarray(
                draw(st.lists(st.floats(0, 2 * math.pi), min_size=n, max_size=n, unique=True))
            )
        )
        return "Polygon", [(cx + r * math.cos(a), cy + r * math.sin(a)) for r, a in zip(radii, ang)]
    if kind in ("rect", "sliver"):
        w = draw(st.floats(1, 400))
        h = draw(st.floats(0.01, 1.0)) if kind == "sliver" else draw(st.floats(1, 400))
        a = draw(st.floats(0, math.pi))
        c, s = math.cos(a), math.sin(a)
        pts = [(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)]
        return "Polygon", [(cx + x * c - y * s, cy + x * s + y * c) for x, y in pts]
    if kind == "point":
        return "Point", [(cx, cy)]
    if kind == "line":
        n = draw(st.integers(2, 5))
        return "LineString", [(cx + draw(coord) / 10, cy + draw(coord) / 10) for _ in range(n)]
    if kind == "collinear":  # a "polygon" whose vertices are collinear (invalid, repaired)
        d = draw(st.floats(1, 200))
        return "Polygon", [(cx, cy), (cx + d, cy + d), (cx + 2 * d, cy + 2 * d)]
    # fewer than 3 distinct points (a degenerate polygon)
    return "Polygon", [(cx, cy), (cx + 5, cy), (cx, cy)]


@st.composite
def sites(draw):
    items = draw(st.lists(shapes(), min_size=1, max_size=6))
    if draw(st.booleans()):
        items.append(items[0])  # an exact duplicate
    return draw(lon0), draw(lat0), items


def feature_collection(lon, lat, items):
    frame = LocalFrame(lon, lat)
    feats = []
    for k, (gtype, pts) in enumerate(items):
        x, y = np.asarray(pts, float).T
        lons, lats = frame.to_wgs84(x, y)
        lons = ((np.asarray(lons) + 180.0) % 360.0) - 180.0
        coords = [[float(a), float(b)] for a, b in zip(lons, lats)]
        if gtype == "Point":
            geom = {"type": "Point", "coordinates": coords[0]}
        elif gtype == "LineString":
            geom = {"type": "LineString", "coordinates": coords}
        else:
            geom = {"type": "Polygon", "coordinates": [coords + [coords[0]]]}
        feats.append(
            {
                "type": "Feature",
                "properties": {"restricted": "yes", "osm_id": str(k)},
                "geometry": geom,
            }
        )
    return {"type": "FeatureCollection", "features": feats}


def read_features(doc, margin):
    rules_doc = {**RULES_DOC, "rule": [{**RULES_DOC["rule"][0], "margin_m": margin}]}
    rules = parse_rules(rules_doc)
    return rules, read_geojson_doc(
        "hypothesis.geojson", doc, rules, [], __import__("collections").Counter()
    )


def polygon_in(verify, lonlat):
    """A fence polygon from output coordinates (lon, lat) in the verifying frame, its edges
    straight lon/lat lines as ArduPilot reads them."""
    return verify.local(shapely.Polygon(np.asarray(lonlat)))


def seamless(geom):
    """Parts of a fence split at the antimeridian, joined again in the verifying frame: their
    shared edges along the meridian project a few nanometres apart (1 micrometre closes
    them), and are no boundary of the fence."""
    return shapely.buffer(geom, 1e-6, join_style="mitre")


def assert_contains(fence_local, restricted, margin, what):
    problem = missing_area(fence_local, restricted, margin)
    assert not problem, f"{what}: {problem}"


SPIKE = [(1.0, 0.0), (2.0, 1e-138), (1.0, 4e-38), (0.54, 0.84), (-0.42, 0.91)]


@example(site=(0.0, 0.0, [("Polygon", SPIKE)]), margin=0.0, method="alpha", max_vertices=4)
@example(
    site=(180.0, 87.4375, [("Point", [(0.0, 0.0)]), ("Polygon", SPIKE)]),
    margin=0.0,
    method="circle",
    max_vertices=4,
)
@example(
    site=(
        179.96875,
        87.0,
        [("Polygon", [(1, 0), (0.9, 0.5), (0.5, 0.8)]), ("Polygon", SPIKE + [(183.4, -53.4)])],
    ),
    margin=0.0,
    method="alpha",
    max_vertices=4,
)
@example(site=(0.0, 0.0, [("Point", [(0.0, 0.0)])]), margin=10.0, method="alpha", max_vertices=4)
@example(  # collinear polygons without area: GEOS 3.11's covers() is off by rounding
    site=(
        0.0,
        0.0,
        [
            ("Polygon", [(0.0, 26.0), (1.0, 27.0), (2.0, 28.0)]),
            ("Polygon", [(0.0, 26.0), (1.5, 27.5), (3.0, 29.0)]),
            ("Polygon", [(0.0, 26.0), (1.0, 27.0), (2.0, 28.0)]),
        ],
    ),
    margin=0.0,
    method="alpha",
    max_vertices=4,
)
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    site=sites(),
    margin=st.sampled_from([0.0, 0.5, 10.0, 100.0]),
    method=st.sampled_from(METHODS),
    max_vertices=st.sampled_from([4, 8, 32]),
)
def test_keep_out_fences_contain_site_plus_margin_in_every_format(
    site, margin, method, max_vertices
):
    lon, lat, items = site
    doc = feature_collection(lon, lat, items)
    rules, features = read_features(doc, margin)
    if not features:
        return  # every input degenerated to nothing (e.g. only invalid empties)
    opts = BuildOptions(method=method, max_vertices=max_vertices, warn_distance_m=20.0)
    result = build_fences(features, rules, opts)
    verify = VerifyFrame(lon, lat)
    widths = []
    for f in features:
        widths.append(
            {"point": rules.point_radius_m, "line": rules.line_width_m / 2}.get(f.geomtype, 0.0)
        )
    geoms = [f.geometry for f in features]
    by_site = {}
    for s in result.sites:
        idx = [i for i, f in enumerate(features) if f.source in s.sources]
        by_site[s.site_id] = [geoms[i] for i in idx], [widths[i] for i in idx]

    # 1. the fences themselves, read back in WGS84, in an independent frame
    for fence in result.fences:
        g, w = by_site[fence.site_id]
        restricted = restricted_in(verify, g, w)
        if fence.circle is not None:
            clon, clat, r = fence.circle_wgs84
            cx, cy = verify.xy(clon, clat)
            pts = shapely.get_coordinates(restricted)
            assert np.all(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) + fence.margin_m <= r + 1e-6), (
                f"circle {fence.site_id}"
            )
        assert_contains(
            seamless(verify.local(fence.geometry)),
            restricted,
            fence.margin_m,
            f"{method} {fence.kind} fence",
        )
        if fence.kind == "keep_out" and method not in ("exact", "circle"):
            for part in shapely.get_parts(fence.local):
                # beyond 85 degrees a fence may take more vertices to hold as it is read
                assert (
                    len(part.exterior.coords) - 1 <= max_vertices
                    or fence.repaired
                    or (abs(lat) > 85.0)
                )

    # 2. every output format
    with tempfile.TemporaryDirectory() as tmp:
        paths = [str(Path(tmp) / n) for n in ("f.geojson", "f.plan", "f.waypoints")]
        from alphafence.fencefiles.atomic import write_all

        write_all(render(result.fences, {}, *paths))
        text = Path(paths[0]).read_text()
        for props, geom in geojson_fences(text):
            g, w = by_site[props["site_id"]]
            assert_contains(
                seamless(verify.local(geom)),
                restricted_in(verify, g, w),
                props["margin_m"],
                "GeoJSON",
            )
        keep_out = [f for f in result.fences if f.kind == "keep_out"]
        for items in (read_plan_fence(paths[1]), read_waypoints_fence(paths[2])):
            polygons, circles = group_polygons(items)
            onboard = [polygon_in(verify, np.asarray(p)) for _, p in polygons]
            # each circle item as ArduPilot measures it: the geodesic circle it surely holds
            centres = [
                (*verify.xy(c.lon, c.lat), circle_inradius_m(c.lon, c.lat, c.param1))
                for c in circles
            ]
            union = seamless(shapely.union_all(onboard)) if onboard else shapely.Polygon()
            for fence in keep_out:
                g, w = by_site[fence.site_id]
                restricted = restricted_in(verify, g, w)
                if fence.circle is not None:
                    # its circle item, checked exactly
                    pts = shapely.get_coordinates(restricted)
                    assert any(
                        np.all(
                            np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) + fence.margin_m <= r + 1e-6
                        )
                        for cx, cy, r in centres
                    ), "no circle item contains the site plus margin"
                    continue
                assert_contains(union, restricted, fence.margin_m, "plan/waypoints")


# -- onboard fences: every profile, corridors of random paths -----------------------------


@st.composite
def paths(draw):
    """A flight path of 1-5 positions among the fences (metres from their origin)."""
    n = draw(st.integers(1, 5))
    return [(draw(st.floats(-3500, 3500)), draw(st.floats(-3500, 3500))) for _ in range(n)]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    fs=fence_sets(),
    path_xy=paths(),
    distance=st.sampled_from([0.0, 200.0, 1000.0, 5000.0]),
    profile=st.sampled_from(sorted(PROFILES)),
    max_items=st.sampled_from([None, 3, 6, 12, 30]),
    keep_in=st.booleans(),
)
def test_onboard_fences_contain_their_fences_for_every_profile_and_corridor(
    fs, path_xy, distance, profile, max_items, keep_in
):
    """Whatever the profile and the flight path: every fence within the distance of the path
    is stored, and the onboard items (read in an independent frame, after merges and rounding)
    contain it (keep-out) or stay inside it (keep-in); every other fence is left out."""
    lon0, lat0, records = fs
    frame = LocalFrame(lon0, lat0)
    x, y = np.asarray(path_xy).T
    lon, lat = frame.to_wgs84(x, y)
    path = flight_path(np.column_stack([lon, lat]))
    if keep_in:  # a keep-in fence from the build: the onboard one must stay inside it
        ring = shapely.Point(0, 0).buffer(6000, quad_segs=3)
        records = [*records, FenceRecord("zone/keep-in", "keep_in", frame.geom_to_wgs84(ring))]
    prof = PROFILES[profile]
    try:
        result = compile_fences(records, path, prof, distance_m=distance, max_items=max_items)
    except InputError as err:  # or, for PX4, a keep-in split at 180°: two inclusions
        assert "do not fit" in str(err) or "PX4 reads them as their intersection" in str(err)
        event("does not fit")
        return
    event("merged" if result.merges else "stored" if result.pieces else "nothing near the path")
    items = result.items
    assert len(items) <= min(prof.items, max_items or prof.items)
    assert storage_bytes(items) <= prof.bytes
    validate_like_ardupilot(items)
    verify = VerifyFrame(lon0, lat0)
    # each circle read by its autopilot's distance (PX4's: tests/px4_model.py)
    inradius = px4_model.circle_inradius_m if prof.autopilot == "px4" else circle_inradius_m
    polys, discs = onboard_geometry(items, verify, inradius)
    path_v = verify.local(path)
    inclusions = [
        polygon_in(verify, np.asarray(pts))
        for cmd, pts in group_polygons(items)[0]
        if cmd == POLYGON_INCLUSION
    ]
    for rec in records:
        local = shapely.make_valid(verify.local(rec.geometry))
        d = local.distance(path_v)
        if rec.site_id in result.dropped:
            assert d > distance - 1.0, f"{rec.site_id} at {d:.1f} m left out"
            continue
        assert d <= distance + 1.0, f"{rec.site_id} at {d:.1f} m stored"
        if rec.kind == "keep_in":
            assert inclusions and all(local.covers(p) for p in inclusions), "keep-in grew"
            continue
        for part in shapely.get_parts(local):
            assert contained(part, polys, discs), f"{rec.site_id} is not inside the onboard fences"


# coordinates as written: 1e-8 degrees (PAD_M of slack) only if rounding is round()'s
halfway = st.builds(
    lambda k, d: (k + 0.5 + d) / 1e8,
    st.integers(-18_000_000_000, 18_000_000_000),
    st.sampled_from([0.0, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5]),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-180, 180), halfway), min_size=1, max_size=40))
def test_geojson_coordinates_are_rounded_as_round_rounds_them(values):
    from alphafence.fencefiles.fence_geojson import DECIMALS, _round_array

    got = _round_array(np.array(values).reshape(-1, 2 if len(values) % 2 == 0 else 1))
    assert got.ravel().tolist() == [round(v, DECIMALS) for v in values]


def _rounded(c, decimals=8):
    """GeoJSON coordinates rounded as Python's ``round`` rounds: 1e-8 degrees, a millimetre
    (written here, apart from the kit's vectorised rounding)."""
    return round(c, decimals) if isinstance(c, float) else [_rounded(x, decimals) for x in c]


def test_geojson_features_are_geos_geojson_rounded():
    """fence_features builds the GeoJSON itself: the same as GEOS's text, rounded, for
    polygons and multipolygons with holes, fences sharing a frame or not."""
    import json

    from alphafence.fencefiles.fence_geojson import fence_features
    from alphafence.fencing.fences import Fence

    holed = shapely.Polygon([(0, 0), (90, 0), (90, 90), (0, 90)], [[(10, 10), (20, 10), (20, 30)]])
    multi = shapely.MultiPolygon([holed, shapely.box(200, 0, 230, 40)])
    here, there = LocalFrame(14.5, 35.9), LocalFrame(179.9999, -60.0)
    fences = [
        Fence(f"s/{k}", None, "s", "keep_out", "exact", 0.0, None, None, [], frame, geom)
        for k, (frame, geom) in enumerate(
            [(here, holed), (here, multi), (there, multi), (there, holed), (here, holed)]
        )
    ]
    for got, f in zip(fence_features(fences), fences):
        want = json.loads(shapely.to_geojson(f.geometry))
        want["coordinates"] = _rounded(want["coordinates"])
        assert got["geometry"] == want
        assert got["properties"]["site_id"] == f.site_id


@settings(max_examples=60, deadline=None)
@given(lon0, lat0, st.floats(1e-4, 0.5), st.integers(0, 2**32 - 1))
def test_frames_are_the_deg_to_rad_aeqd_pipeline_bit_for_bit(lon, lat, span, seed):
    """LocalFrame builds the projection alone and scales degrees itself: the numbers must be
    those of the PROJ pipeline "unitconvert deg -> rad, then aeqd", both ways."""
    import pyproj

    pipeline = pyproj.Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
        f"+step +proj=aeqd +lat_0={lat!r} +lon_0={lon!r} +ellps=WGS84"
    )
    frame = LocalFrame(lon, lat)
    rng = np.random.default_rng(seed)
    lons = lon + rng.uniform(-span, span, 64)
    lats = np.clip(lat + rng.uniform(-span, span, 64), -90, 90)
    assert np.array_equal(frame.to_local(lons, lats), pipeline.transform(lons, lats))
    x, y = rng.uniform(-span, span, (2, 64)) * 111e3
    lon_w, lat_w = pipeline.transform(x, y, direction="INVERSE")
    got = frame.to_wgs84(x, y)
    assert np.array_equal(got[0], np.where(np.abs(lon_w) > 180, (lon_w + 180) % 360 - 180, lon_w))
    assert np.array_equal(got[1], lat_w)


# -- circle zones (ED-269, ED-318): one circle fence, the zone plus margin inside it -------


def circle_zone_doc(lon, lat, radius, uom, ed318):
    """One circle zone as ED-269 (``uomDimensions``) or ED-318 (a Point with a Circle extent)
    writes it."""
    if ed318:
        layer = {"lower": 0, "upper": 120, "uom": "m"}
        geom = {"type": "Point", "coordinates": [lon, lat], "layer": layer}
        geom["extent"] = {"subType": "Circle", "radius": radius}
        props = {"identifier": "Z", "type": "PROHIBITED", "variant": "COMMON"}
        return {
            "type": "FeatureCollection",
            "features": [{"type": "Feature", "properties": props, "geometry": geom}],
        }
    projection = {"type": "Circle", "center": [lon, lat], "radius": radius}
    entry = {
        "uomDimensions": uom,
        "lowerLimit": 0,
        "upperLimit": 120,
        "horizontalProjection": projection,
    }
    return {"features": [{"identifier": "Z", "restriction": "PROHIBITED", "geometry": [entry]}]}


def true_circle(lon, lat, radius_m, n=720):
    """Points of the zone's geodesic circle (pyproj's Geod, not the kit's frames)."""
    az = np.linspace(-180.0, 180.0, n, endpoint=False)
    lons, lats, _ = GEOD.fwd(np.full(n, lon), np.full(n, lat), az, np.full(n, radius_m))
    return lons, lats


def circle_holds(circle_lonlat_r, zone_pts, margin):
    """Every point of the zone at least ``margin`` inside the circle, geodesically."""
    clon, clat, r = circle_lonlat_r
    lons, lats = zone_pts
    n = len(lons)
    d = GEOD.inv(np.full(n, clon), np.full(n, clat), lons, lats)[2]
    return bool(np.all(d + margin <= r + 1e-6))


@example(
    lon=179.999, lat=89.5, radius=20_000.0, uom="FT", ed318=False, margin=100.0, method="exact"
)
@example(lon=-180.0, lat=-89.5, radius=20_000.0, uom="M", ed318=True, margin=0.0, method="alpha")
@example(lon=180.0, lat=0.0, radius=1.0, uom="M", ed318=False, margin=0.0, method="circle")
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    lon=lon0,
    lat=lat0,
    radius=st.one_of(st.floats(1, 500), st.floats(500, 20_000)),
    uom=st.sampled_from(["M", "FT"]),
    ed318=st.booleans(),
    margin=st.sampled_from([0.0, 0.5, 10.0, 100.0]),
    method=st.sampled_from(METHODS),
)
def test_a_circle_zone_is_one_circle_fence_holding_it_plus_margin_in_every_format(
    lon, lat, radius, uom, ed318, margin, method
):
    from collections import Counter

    from alphafence.zones.ed269 import read_ed269_doc

    rules = parse_rules(
        {"rule": [{"category": "zone", "kind": "keep_out", "tags": {"ed269:restriction": "*"}}]}
    )
    doc = circle_zone_doc(lon, lat, radius, uom, ed318)
    features = read_ed269_doc("zone.json", doc, rules, [], Counter())
    radius_m = radius * (0.3048 if uom == "FT" and not ed318 else 1.0)
    opts = BuildOptions(method=method, margin_m=margin, warn_distance_m=20.0)
    result = build_fences(features, rules, opts)
    zone = true_circle(lon, lat, radius_m)
    assert [f.kind for f in result.fences] == ["keep_out", "warning"]
    for fence in result.fences:
        assert fence.circle is not None and not fence.repaired
        assert circle_holds(fence.circle_wgs84, zone, fence.margin_m), fence.kind
        # its polygon (drawn in GeoJSON) holds it too, in an independent frame
        verify = VerifyFrame(lon, lat)
        x, y = verify.xy(*zone)
        pts = shapely.points(np.column_stack([x, y]))
        poly = verify.local(fence.geometry)
        assert np.all(shapely.covers(poly, pts))
        assert float(np.min(shapely.distance(poly.exterior, pts))) >= fence.margin_m - 1e-6
    with tempfile.TemporaryDirectory() as tmp:
        paths = [str(Path(tmp) / n) for n in ("f.geojson", "f.plan", "f.waypoints")]
        from alphafence.fencefiles.atomic import write_all

        write_all(render(result.fences, {}, *paths))
        for props, _ in geojson_fences(Path(paths[0]).read_text()):
            circle = (*props["center"], props["radius_m"])
            assert circle_holds(circle, zone, props["margin_m"]), "GeoJSON"
        for items in (read_plan_fence(paths[1]), read_waypoints_fence(paths[2])):
            polygons, circles = group_polygons(items)
            assert not polygons and len(circles) == 1  # one circle item: 13 bytes onboard
            (c,) = circles
            # the item as ArduPilot measures it: the geodesic circle it surely holds
            held = (c.lon, c.lat, circle_inradius_m(c.lon, c.lat, c.param1))
            assert circle_holds(held, zone, margin), "plan/waypoints"


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    groups=st.lists(
        st.tuples(sites(), st.sampled_from(["restricted", "caution", "allowed"])),
        min_size=3,
        max_size=12,
    ),
    margin=st.sampled_from([0.0, 10.0]),
    method=st.sampled_from(METHODS),
)
def test_fence_sites_all_at_once_equal_one_at_a_time(groups, margin, method):
    """fence_sites makes every stage for many sites at once (vectorised GEOS calls, the
    containment checks of many fences in one call): the fences must be those made site by
    site, to the last bit, for keep-out, warning and keep-in sites of every method."""
    from alphafence.fencing.fences import fence_sites, site_fences
    from alphafence.fencing.sites import group_sites

    kinds = {"restricted": "keep_out", "caution": "warning", "allowed": "keep_in"}
    rules = parse_rules(
        {
            "defaults": RULES_DOC["defaults"],
            "rule": [
                {"category": tag, "kind": kind, "tags": {tag: "*"}, "margin_m": margin}
                for tag, kind in kinds.items()
            ],
        }
    )
    features = []
    for k, ((lon, lat, items), tag) in enumerate(groups):
        doc = feature_collection(lon, lat, items)
        for feat in doc["features"]:
            feat["properties"] = {tag: "yes", "osm_id": f"{k}.{feat['properties']['osm_id']}"}
        features += read_geojson_doc(
            "h.geojson", doc, rules, [], __import__("collections").Counter()
        )
    all_sites = group_sites(features, rules)
    opts = BuildOptions(method=method, max_vertices=8, warn_distance_m=20.0)
    try:
        one = [f for s in all_sites for f in site_fences(s, opts)]
    except ValueError:  # a keep-in site vanishing inside its margin: so must all at once
        with pytest.raises(ValueError):
            fence_sites(all_sites, opts)
        return
    many = fence_sites(all_sites, opts)
    event(f"{min(len(all_sites) // 8, 2) * 8}+ sites")
    event(f"repaired: {any(f.repaired for f in one)}")
    assert len(many) == len(one)
    for a, b in zip(one, many):
        assert (a.site_id, a.kind, a.method, a.margin_m, a.circle, a.alpha_m, a.repaired) == (
            b.site_id, b.kind, b.method, b.margin_m, b.circle, b.alpha_m, b.repaired
        )  # fmt: skip
        assert type(a.margin_m) is type(b.margin_m)
        assert shapely.to_wkb(a.local) == shapely.to_wkb(b.local)
