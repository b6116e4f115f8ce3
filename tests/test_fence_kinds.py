"""Keep-in fences, warning layers, ED-269 properties carried to the fences."""

import json

import shapely

from alphafence.fencing.fences import contains_with_margin
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.zones.database import read_database

AREA = {
    "type": "FeatureCollection",
    "features": [
        {
            "type": "Feature",
            "properties": {
                "name": "Operating area",
                "alphafence:kind": "keep_in",
                "osm_way_id": "1",
            },
            "geometry": {
                "type": "Polygon",
                "coordinates": [
                    [
                        [14.50, 35.85],
                        [14.52, 35.85],
                        [14.52, 35.86],
                        [14.51, 35.855],
                        [14.50, 35.86],
                        [14.50, 35.85],
                    ]
                ],
            },
        },
        {
            "type": "Feature",
            "properties": {"amenity": "hospital", "osm_way_id": "2"},
            "geometry": {
                "type": "Polygon",
                "coordinates": [
                    [
                        [14.505, 35.852],
                        [14.506, 35.852],
                        [14.506, 35.853],
                        [14.505, 35.853],
                        [14.505, 35.852],
                    ]
                ],
            },
        },
    ],
}


def test_keep_in_fence_lies_inside_the_area_minus_its_margin(write_json, rules):
    db = read_database([write_json("area.geojson", AREA)], rules)
    for method in ("alpha", "polygon", "circle", "exact"):
        result = build_fences(db.features, rules, BuildOptions(method=method, max_vertices=4))
        keep_in = [f for f in result.fences if f.kind == "keep_in"]
        assert len(keep_in) == 1, method
        fence = keep_in[0]
        site = next(s for s in result.sites if s.site_id == fence.site_id)
        allowed = site.geometry.buffer(-fence.margin_m, quad_segs=64)
        assert allowed.buffer(1e-6).covers(fence.local), method
        assert fence.local.area > 0.5 * allowed.area or method == "circle", method
        if method != "exact" and fence.circle is None:
            assert len(fence.local.exterior.coords) - 1 <= 5
        # keep-in fences get no warning layer; keep-out ones do, and it contains them
        out = [f for f in result.fences if f.kind == "keep_out"]
        warn = [f for f in result.fences if f.kind == "warning"]
        assert len(out) == len(warn) == 1
        site_out = next(s for s in result.sites if s.kind == "keep_out")
        assert contains_with_margin(
            warn[0].local, warn[0].circle, site_out.geometry, out[0].margin_m + 30.0
        )


def test_ed269_applicability_reaches_the_fence_geojson(tmp_path):
    from alphafence.cli import main
    from tests.test_readers import ED269

    src = tmp_path / "zones.json"
    src.write_text(json.dumps(ED269))
    out = tmp_path / "f.geojson"
    assert main(["build", str(src), "-o", str(out), "-q"]) == 0
    feats = json.loads(out.read_text())["features"]
    p1 = next(
        f["properties"]
        for f in feats
        if f["properties"]["sources"] == ["EX-P1"] and f["properties"]["kind"] == "keep_out"
    )
    assert p1["zone"]["restriction"] == "PROHIBITED"
    assert p1["zone"]["applicability"][0]["endDateTime"] == "2026-12-01T00:00:00Z"
    assert p1["alt_max_m"] == 121.92
    circle = next(f for f in feats if f["properties"]["sources"] == ["EX-C1"])
    assert circle["properties"]["kind"] == "warning"
    assert shapely.geometry.shape(circle["geometry"]).is_valid
