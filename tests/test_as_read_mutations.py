"""The as-read checks of tests/test_as_read_properties.py can fail: each is run on a fence
broken on purpose (moved, shrunk by its margin, touching its zone between the old samples,
a zone dropped, a keep-in area split in two without the union, an onboard fence moved, a
circle moved) and must say so. These broken cases stay in the suite so the checks stay able
to fail."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
import shapely

from alphafence.fencefiles.atomic import write_all
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.fencefiles.qgc_plan import dumps, plan_document
from alphafence.fencing.outputs import render
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_EXCLUSION, POLYGON_INCLUSION, FenceItem
from alphafence.mavlink.storage import PROFILES
from alphafence.onboard.compile import compile_fences

from .test_as_read_properties import (
    _features,
    _holds,
    _keep_in_outputs,
    _keep_out_outputs,
    _onboard_holds,
    _rings,
    _rules,
    _strip,
)

ZONE = _strip(14.0, 45.0, 70.0, 10_000.0, 2_000.0)  # 10 km long, at 45 degrees north
MARGIN = 10.0


def keep_out(method="alpha"):
    rules = _rules("keep_out", MARGIN)
    return build_fences(_features([ZONE], rules), rules, BuildOptions(method=method))


def test_the_fence_as_built_holds():  # the unbroken case: the checks below fail for a reason
    _keep_out_outputs(keep_out(), [ZONE])


def test_a_moved_fence_fails():
    fence = [f for f in keep_out().fences if f.kind == "keep_out"][0]
    moved = [r + np.array([0.001, 0.0]) for r in _rings(fence.geometry)]  # about 80 m east
    with pytest.raises(AssertionError, match="not inside"):
        _holds(ZONE, moved, [], MARGIN, "moved")


def test_a_fence_shrunk_by_its_margin_fails():
    frame = LocalFrame(14.0, 45.0)  # the zone and a metre, not its 10 m margin
    tight = frame.geom_to_wgs84(frame.geom_to_local(ZONE).buffer(1.0, join_style="mitre"))
    _holds(ZONE, _rings(tight), [], 0.0, "a metre around the zone")  # it covers the zone
    with pytest.raises(AssertionError, match="reaches"):
        _holds(ZONE, _rings(tight), [], MARGIN, "a metre around the zone")


def test_a_fence_touching_its_zone_between_the_old_samples_fails():
    """A fence 10 m clear of its zone but for one notch reaching 3 m from it, midway between
    samples 50 m apart (the old spacing): the margin check sees it."""
    frame = LocalFrame(14.0, 45.0)
    zone = frame.geom_to_wgs84(shapely.box(0, 0, 1000, 200))
    ring = [(-10, -10), (500 - 25, -10), (500 - 25 + 12.5, -3), (500, -10), (1010, -10),
            (1010, 210), (-10, 210)]  # fmt: skip
    fence = np.asarray(frame.geom_to_wgs84(shapely.Polygon(ring)).exterior.coords)[:-1]
    _holds(zone, [fence], [], 2.0, "3 m clear of a 2 m margin")  # it holds a 2 m margin
    with pytest.raises(AssertionError, match="reaches"):
        _holds(zone, [fence], [], MARGIN, "the notch")


def test_a_dropped_zone_fails():
    other = _strip(15.0, 45.0, 70.0, 10_000.0, 2_000.0)
    rules = _rules("keep_out", MARGIN)
    result = build_fences(_features([ZONE, other], rules), rules, BuildOptions(method="alpha"))
    result.fences = [f for f in result.fences if not f.sources[0].endswith("/1")]
    with pytest.raises(AssertionError, match="without a fence"):
        _keep_out_outputs(result, [ZONE, other])


def test_a_moved_circle_fails():
    fence = [f for f in keep_out("circle").fences if f.kind == "keep_out"][0]
    lon, lat, r = fence.circle_wgs84
    _holds(ZONE, [], [(lon, lat, r + 1.0)], MARGIN, "the circle")
    with pytest.raises(AssertionError, match="out of the circle"):
        _holds(ZONE, [], [(lon + 0.002, lat, r + 1.0)], MARGIN, "moved")


def test_a_keep_in_area_split_without_the_union_fails(monkeypatch):
    """One keep-in area written as two inclusion polygons (its halves) and no word of the
    union: the vehicle, intersecting them, would call the area itself a breach."""
    rules = _rules("keep_in", MARGIN)
    result = build_fences(_features([ZONE], rules), rules, BuildOptions(method="alpha"))
    _keep_in_outputs(result, ZONE, MARGIN)  # as built: one inclusion, it holds

    def halves(fences):
        (fence,) = [f for f in fences if f.kind == "keep_in"]
        x0, y0, x1, y1 = fence.geometry.bounds
        cut = [shapely.box(x0 - 1, y0 - 1, (x0 + x1) / 2, y1 + 1),
               shapely.box((x0 + x1) / 2, y0 - 1, x1 + 1, y1 + 1)]  # fmt: skip
        items = []
        for half in cut:
            ring = np.asarray(shapely.intersection(fence.geometry, half).exterior.coords)[:-1]
            items += [FenceItem(POLYGON_INCLUSION, float(len(ring)), x, y) for x, y in ring]
        return items

    import alphafence.fencing.outputs as outputs
    from alphafence.fencefiles import qgc_plan

    monkeypatch.setattr(outputs, "fence_items", halves)
    # the broken writer forgets the union: the plan says nothing of FENCE_OPTIONS
    monkeypatch.setattr(qgc_plan, "inclusion_count", lambda items: 1)
    with pytest.raises(AssertionError):
        _keep_in_outputs(result, ZONE, MARGIN)


def test_an_onboard_fence_moved_away_fails():
    fences = [f for f in keep_out().fences if f.kind == "keep_out"]
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "f.geojson")
        write_all(render(fences, {}, path))
        records = read_fence_file(path)
    area = shapely.box(*records[0].geometry.bounds)
    onboard = compile_fences(records, area, PROFILES["copter"])
    _onboard_holds(records, onboard.items)
    moved = [FenceItem(i.command, i.param1, i.lon + 1.0, i.lat) for i in onboard.items]
    assert all(i.command == POLYGON_EXCLUSION for i in moved)  # no circle hides the move
    with pytest.raises(AssertionError, match="stand outside"):
        _onboard_holds(records, moved)


def test_a_plan_with_two_inclusions_says_it_needs_the_union():
    two = [FenceItem(POLYGON_INCLUSION, 3.0, x, y) for x, y in ((0, 0), (1, 0), (0, 1))] * 2
    doc = json.loads(dumps(plan_document(two)))
    assert doc["geoFence"]["alphafence"]["inclusion_areas"] == 2
