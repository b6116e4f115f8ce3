"""Safety invariant, property-tested: every keep-out (and warning) fence contains its site's
restricted area buffered by its margin, for every method, in every output format (the
in-memory fence, GeoJSON, QGroundControl .plan, ArduPilot waypoints), after simplification.
Sites are random and degenerate: collinear points, duplicates, < 3 points, slivers,
point-only, multi-part, near the antimeridian and at high latitude."""

import math
import tempfile
from pathlib import Path

import numpy as np
import shapely
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from alphafence.build.fences import METHODS
from alphafence.build.outputs import render
from alphafence.build.pipeline import BuildOptions, build_fences
from alphafence.formats.geojson import read_geojson_doc
from alphafence.formats.qgc_plan import group_polygons, read_plan_fence
from alphafence.formats.qgc_wpl import read_waypoints_fence
from alphafence.formats.rules import parse_rules
from alphafence.geo.frame import LocalFrame

from .helpers import VerifyFrame, geojson_fences, missing_area, restricted_in

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
    """A fence polygon from output coordinates (lon, lat) in the verifying frame."""
    x, y = verify.xy(np.asarray(lonlat)[:, 0], np.asarray(lonlat)[:, 1])
    return shapely.Polygon(np.column_stack([x, y]))


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
            verify.local(fence.geometry), restricted, fence.margin_m, f"{method} {fence.kind} fence"
        )
        if fence.kind == "keep_out" and method not in ("exact", "circle"):
            for part in shapely.get_parts(fence.local):
                assert len(part.exterior.coords) - 1 <= max_vertices or fence.repaired

    # 2. every output format
    with tempfile.TemporaryDirectory() as tmp:
        paths = [str(Path(tmp) / n) for n in ("f.geojson", "f.plan", "f.waypoints")]
        from alphafence.formats.atomic import write_all

        write_all(render(result.fences, {}, *paths))
        text = Path(paths[0]).read_text()
        for props, geom in geojson_fences(text):
            g, w = by_site[props["site_id"]]
            assert_contains(
                verify.local(geom), restricted_in(verify, g, w), props["margin_m"], "GeoJSON"
            )
        keep_out = [f for f in result.fences if f.kind == "keep_out"]
        for items in (read_plan_fence(paths[1]), read_waypoints_fence(paths[2])):
            polygons, circles = group_polygons(items)
            onboard = [polygon_in(verify, np.asarray(p)) for _, p in polygons]
            centres = [(*verify.xy(c.lon, c.lat), c.param1) for c in circles]
            union = shapely.union_all(onboard) if onboard else shapely.Polygon()
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
