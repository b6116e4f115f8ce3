"""Many regions grouped into sites at once (fencing/sites.py ``regions_sites``) give, bit for bit,
the sites of grouping them one region at a time: the same members, names, frames, and parts
to the last coordinate. Property-tested on random regions of boxes, points, lines and
invalid polygons, near the antimeridian, at high latitude, and regions wider than 20 km
(whose sites take frames of their own)."""

from __future__ import annotations

import math

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.fencing.sites import (
    _region_sites,
    feature_widths,
    group_sites,
    regions_sites,
)
from alphafence.zones.features import Feature
from alphafence.zones.rules import parse_rules

RULES = parse_rules(
    {
        "defaults": {"point_radius_m": 20.0, "line_width_m": 8.0},
        "rule": [{"category": "school", "kind": "keep_out", "tags": {"amenity": "school"}}],
    }
)
RULE = RULES.match({"amenity": "school"}.get, "area")
M_PER_DEG = 111_320.0


@st.composite
def region(draw, number):
    """One region's features around a random centre: boxes, points, lines, a bow-tie."""
    lat0 = draw(st.sampled_from([35.9, 69.5, -33.75, 0.0]))
    lon0 = draw(st.sampled_from([14.5, -77.5, 179.999, -179.999]))
    spread = draw(st.sampled_from([300.0, 30_000.0]))  # a region wider than 20 km, sometimes
    n = draw(st.integers(1, 6))
    out = []
    for k in range(n):
        x = draw(st.floats(-spread, spread)) / (M_PER_DEG * math.cos(math.radians(lat0)))
        y = draw(st.floats(-spread, spread)) / M_PER_DEG
        lon, lat = lon0 + x, lat0 + y
        kind = draw(st.sampled_from(["box", "point", "line", "bowtie"]))
        w = draw(st.floats(2, 80)) / M_PER_DEG
        if kind == "box":
            geom = shapely.box(lon, lat, lon + w, lat + w)
        elif kind == "point":
            geom = shapely.Point(lon, lat)
        elif kind == "line":
            geom = shapely.LineString([(lon, lat), (lon + w, lat + w / 2)])
        else:  # self-intersecting: repaired before grouping
            geom = shapely.Polygon([(lon, lat), (lon + w, lat + w), (lon + w, lat), (lon, lat + w)])
        tags = {"amenity": "school", "name": f"s{number}-{k}"} if k % 2 else {"amenity": "school"}
        out.append(Feature(geom, tags, f"way/{number}-{k}", "test", RULE))
    return out


@st.composite
def regions(draw):
    return [draw(region(number)) for number in range(draw(st.integers(1, 5)))]


def assert_same_sites(one, other):
    assert len(one) == len(other)
    for a, b in zip(one, other):
        assert (a.site_id, a.name, a.sources, a.kind, a.margin_m) == (
            b.site_id,
            b.name,
            b.sources,
            b.kind,
            b.margin_m,
        )
        assert (a.frame.lon0, a.frame.lat0) == (b.frame.lon0, b.frame.lat0)
        assert [f.source for f in a.features] == [f.source for f in b.features]
        assert len(a.parts) == len(b.parts)
        assert all(shapely.to_wkb(p) == shapely.to_wkb(q) for p, q in zip(a.parts, b.parts))


@settings(max_examples=80, deadline=None)
@given(groups=regions())
def test_regions_at_once_are_regions_one_by_one(groups):
    features = [f for g in groups for f in g]
    ends = np.cumsum([len(g) for g in groups]).tolist()
    spans = list(zip([0, *ends[:-1]], ends))
    at_once = regions_sites(features, spans, RULES, 25.0)
    one_by_one = []
    for g in groups:
        geoms = np.array([f.geometry for f in g], dtype=object)
        one_by_one.extend(_region_sites(g, geoms, feature_widths(g, RULES), 25.0))
    assert_same_sites(at_once, one_by_one)


def test_group_sites_of_a_wide_and_a_small_region():
    # a campus of two buildings 18 m apart, and a line 54 km long with a box 11 m from its
    # end: one site whose region is wider than 20 km
    campus = [
        Feature(shapely.box(14.5, 35.9, 14.5005, 35.9004), {}, "way/1", "t", RULE),
        Feature(shapely.box(14.5007, 35.9, 14.5012, 35.9004), {}, "way/2", "t", RULE),
    ]
    long_line = Feature(shapely.LineString([(15.0, 36.0), (15.6, 36.0)]), {}, "way/3", "t", RULE)
    far_box = Feature(shapely.box(15.59, 36.0001, 15.591, 36.0011), {}, "way/4", "t", RULE)
    sites = group_sites([*campus, long_line, far_box], RULES, 25.0)
    assert [s.sources for s in sites] == [["way/1", "way/2"], ["way/3", "way/4"]]
    # the 54 km region's site has its own frame, centred on the site
    wide = sites[1]
    assert abs(wide.frame.lon0 - 15.3) < 1e-9 and abs(wide.frame.lat0 - 36.00055) < 1e-9
