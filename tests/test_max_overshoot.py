"""A vertex budget by error, not only by count: long overlapping military strips at 60 to 67°N
built into one site. At 6 vertices the fence is several times the strips' area and the build's
summary says so; with ``--max-overshoot`` no point of the fence lies farther than
that from the shape its method drew, it takes the vertices it needs, and it still holds the
strips plus margin as ArduPilot reads it."""

from __future__ import annotations

import json

import numpy as np
import shapely

from alphafence.cli import main

from .ardupilot_model import covers_as_read, excursion_m

STRIPS = [
    shapely.Polygon([(12.0, 60.1), (24.0, 66.2), (24.2, 66.1), (12.2, 60.0)]),
    shapely.Polygon([(12.0, 66.0), (24.0, 60.2), (24.2, 60.3), (12.2, 66.1)]),
    shapely.box(11.0, 63.0, 25.0, 63.15),
]


def _database(tmp_path):
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"military": "danger_area", "name": f"strip {k}"},
                "geometry": shapely.geometry.mapping(z),
            }
            for k, z in enumerate(STRIPS)
        ],
    }
    path = tmp_path / "strips.geojson"
    path.write_text(json.dumps(doc))
    return path


def _build(tmp_path, capsys, *extra):
    out = tmp_path / f"fences{len(extra)}.geojson"
    args = ["build", str(_database(tmp_path)), "-o", str(out), "--warn-distance", "0"]
    args += ["--max-vertices", "6", *extra]
    assert main(args) == 0
    err = capsys.readouterr().err
    doc = json.loads(out.read_text())
    (fence,) = [f for f in doc["features"] if f["properties"]["kind"] == "keep_out"]
    return shapely.geometry.shape(fence["geometry"]), fence["properties"], doc["alphafence"], err


def test_a_vertex_cap_that_makes_a_fence_far_larger_is_said_and_max_overshoot_bounds_it(
    tmp_path, capsys
):
    capped, props, meta, err = _build(tmp_path, capsys)
    assert "--max-overshoot M bounds it" in " ".join(err.split())
    assert "max_overshoot_m" not in meta
    bounded, props_b, meta_b, err_b = _build(tmp_path, capsys, "--max-overshoot", "2000")
    assert meta_b["max_overshoot_m"] == 2000.0
    assert "bounds it" not in err_b
    assert props_b["vertices"] > props["vertices"]
    # as read: the strips plus margin inside both fences, the bounded one far tighter
    margin = props["margin_m"]
    for fence in (capped, bounded):
        rings = [np.asarray(p.exterior.coords)[:-1] for p in shapely.get_parts(fence)]
        for strip in STRIPS:
            assert covers_as_read(rings, strip)  # exactly, and the margin to a tenth of it
            assert excursion_m(strip, rings, margin) == 0.0
    strips = shapely.union_all(STRIPS)
    assert shapely.area(bounded) < 0.6 * shapely.area(capped)
    assert shapely.area(bounded) < 1.3 * shapely.area(strips)
