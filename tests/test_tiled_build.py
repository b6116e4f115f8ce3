"""The build in tiles (fencing/tiled.py) gives exactly the untiled build: the same sites with the
same features, the same fences to the last bit, whatever the tile size, the job size, the
number of worker processes or a Dask cluster. Property-tested on random features placed
across tile edges, and checked on Malta's OSM extract."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.fencing.tiled import build_tiled
from alphafence.fencing.tiles import plan_jobs
from alphafence.zones.database import DatabaseStream, read_database
from alphafence.zones.rules import load_rules, parse_rules
from tests.test_regions import _regions_at_once

RULES = parse_rules(
    {
        "defaults": {"point_radius_m": 20.0, "line_width_m": 8.0},
        "rule": [
            {"category": "school", "kind": "keep_out", "tags": {"amenity": "school"}},
            {"category": "park", "kind": "warning", "tags": {"leisure": "park"}},
        ],
    }
)
M_PER_DEG = 111_320.0


def _write_seq(path, shapes):
    with open(path, "w") as fh:
        for i, (tag, geom) in enumerate(shapes):
            props = {"amenity": "school"} if tag == "school" else {"leisure": "park"}
            props["@id"] = f"way/{i}"
            gj = json.loads(shapely.to_geojson(geom))
            fh.write(json.dumps({"type": "Feature", "geometry": gj, "properties": props}) + "\n")


@st.composite
def scenes(draw):
    """Features within a few hundred metres of a tile corner: chains that join across edges,
    points, lines and boxes, two classes."""
    lat0 = draw(st.sampled_from([35.0, 60.0, -33.75]))
    lon0 = draw(st.sampled_from([14.25, -77.5, 179.75]))
    n = draw(st.integers(1, 14))
    shapes = []
    for _ in range(n):
        x = draw(st.floats(-300, 300)) / (M_PER_DEG * math.cos(math.radians(lat0)))
        y = draw(st.floats(-300, 300)) / M_PER_DEG
        kind = draw(st.sampled_from(["box", "point", "line"]))
        if kind == "box":
            w = draw(st.floats(2, 80)) / M_PER_DEG
            geom = shapely.box(lon0 + x, lat0 + y, lon0 + x + w, lat0 + y + w)
        elif kind == "point":
            geom = shapely.Point(lon0 + x, lat0 + y)
        else:
            d = draw(st.floats(5, 120)) / M_PER_DEG
            geom = shapely.LineString([(lon0 + x, lat0 + y), (lon0 + x + d, lat0 + y + d / 2)])
        if geom.bounds[2] > 180:  # stay on this side of the antimeridian
            geom = shapely.transform(geom, lambda c: c - [0.01, 0])
        shapes.append((draw(st.sampled_from(["school", "school", "park"])), geom))
    return shapes


def _by_site(fences):
    return {(f.site_id, f.kind): f for f in fences}


def assert_same_build(untiled, tiled):
    """Same sites (ids and members) and the same fences, bit for bit."""
    assert {s.site_id: s.sources for s in untiled.sites} == {
        s.site_id: s.sources for s in tiled.site_objects
    }
    a, b = _by_site(untiled.fences), _by_site(tiled.fences)
    assert a.keys() == b.keys()
    for key in a:
        assert shapely.equals_exact(a[key].geometry, b[key].geometry, 0), key
        assert a[key].sources == b[key].sources


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(shapes=scenes(), tile=st.sampled_from([0.001, 0.002, 0.25]), target=st.integers(1, 6))
def test_tiles_give_the_untiled_build(tmp_path, shapes, tile, target):
    path = tmp_path / "scene.geojsonl"
    _write_seq(path, shapes)
    options = BuildOptions(join_m=25.0)
    untiled = build_fences(read_database(str(path), RULES).features, RULES, options)
    tiled = build_tiled(
        DatabaseStream(str(path), RULES),
        RULES,
        options,
        jobs=1,
        keep=True,
        tile_deg=tile,
        target=target,
    )
    assert tiled.sites == len(untiled.sites)
    assert_same_build(untiled, tiled)


def test_a_chain_across_many_tiles_stays_one_site():
    # 40 boxes 20 m apart in a line 2.4 km long, tiles of about 110 m: one site, one job
    lon = 14.25 + np.arange(40) * 60 / (M_PER_DEG * math.cos(math.radians(35)))
    boxes = shapely.box(lon, 35.0, lon + 40 / M_PER_DEG / 0.819, 35.0 + 40 / M_PER_DEG)
    bounds = shapely.bounds(boxes)
    jobs = plan_jobs(bounds, np.zeros(40), np.zeros(40, int), 25.0, tile_deg=0.001, target=1)
    assert len(jobs) == 1 and len(jobs[0].regions) == 1 and len(jobs[0].regions[0]) == 40
    # regions grow each extent by the whole join (+1 m): at 8 m, 2 x 9 m < the 20 m gaps
    apart = plan_jobs(bounds, np.zeros(40), np.zeros(40, int), 8.0, tile_deg=0.001, target=1)
    assert len(apart) == 40


def test_every_feature_is_in_exactly_one_job():
    rng = np.random.default_rng(5)
    xy = rng.uniform([14.0, 35.0], [14.5, 35.5], size=(3000, 2))
    bounds = np.c_[xy, xy + 0.0003]
    classes = rng.integers(0, 3, 3000)
    jobs = plan_jobs(bounds, np.zeros(3000), classes, 25.0, tile_deg=0.05, target=100)
    seen = np.concatenate([r for j in jobs for r in j.regions])
    assert np.array_equal(np.sort(seen), np.arange(3000))
    assert [j.number for j in jobs] == list(range(len(jobs)))
    for job in jobs:
        for region in job.regions:
            assert len(set(classes[region])) == 1  # classes never share a region


@pytest.fixture(scope="module")
def malta_untiled(malta):
    rules = load_rules()
    db = read_database(str(malta), rules)
    return str(malta), rules, build_fences(db.features, rules, BuildOptions())


def test_malta_in_worker_processes_is_the_untiled_build(malta_untiled):
    malta, rules, untiled = malta_untiled
    tiled = build_tiled(
        DatabaseStream(malta, rules), rules, BuildOptions(), jobs=2, keep=True, target=50
    )
    assert tiled.jobs > 2
    assert_same_build(untiled, tiled)


def test_malta_on_a_local_dask_cluster_is_the_untiled_build(malta_untiled):
    distributed = pytest.importorskip("distributed")
    malta, rules, untiled = malta_untiled
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        with distributed.Client(cluster) as client:
            client.wait_for_workers(2)
            tiled = build_tiled(
                DatabaseStream(malta, rules),
                rules,
                BuildOptions(),
                dask=cluster.scheduler_address,
                keep=True,
                target=50,
            )
    assert tiled.jobs > 2
    assert_same_build(untiled, tiled)


def test_item_counts_are_what_fence_items_makes(malta_untiled):
    from alphafence.mavlink.items import fence_items, item_count

    _, _, untiled = malta_untiled
    counted = [item_count(f) for f in untiled.fences]
    assert counted == [len(fence_items([f])) for f in untiled.fences]
    assert sum(counted) > 0 and 0 in counted  # polygons, circles' kin and warning layers


def _plan_by_hand(bounds, widths, classes, join_m, tile_deg, target):
    """The plan written plainly: regions (one R-tree over all), each in the tile of its
    extent's centre, tiles row by row and then the database's order, a job closing once it
    holds the target. Lists of (tiles, regions) per job."""
    labels = _regions_at_once(bounds, widths, classes, join_m)
    regions = [np.flatnonzero(labels == k) for k in range(int(labels.max()) + 1)]
    keyed = []
    for members in regions:
        lo, hi = bounds[members, :2].min(axis=0), bounds[members, 2:].max(axis=0)
        centre = (lo + hi) / 2.0
        row = math.floor((centre[1] + 90.0) / tile_deg)
        col = math.floor((centre[0] + 180.0) / tile_deg)
        keyed.append(((row, col, int(members[0])), members))
    keyed.sort(key=lambda k: k[0])
    jobs, size = [], target
    for (row, col, _), members in keyed:
        if size >= target:
            jobs.append(([], []))
            size = 0
        tiles, rs = jobs[-1]
        if not tiles or tiles[-1] != (row, col):
            tiles.append((row, col))
        rs.append(members.tolist())
        size += len(members)
    return jobs


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 300),
    seed=st.integers(0, 2**32 - 1),
    tile=st.sampled_from([0.001, 0.003, 0.25]),
    target=st.integers(1, 40),
    kinds=st.integers(1, 3),
)
def test_the_plan_is_the_plan_written_plainly(n, seed, tile, target, kinds):
    """Jobs hold whole regions in their tiles' order, packed greedily, as written plainly."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([14.24, 34.99], [14.26, 35.01], size=(n, 2))  # across tile corners
    bounds = np.round(np.c_[xy, xy + rng.uniform(0, 0.001, size=(n, 2))], 5)
    widths = rng.choice([0.0, 5.0, 20.0], n)
    classes = rng.integers(0, kinds, n)
    plan = plan_jobs(bounds, widths, classes, 25.0, tile_deg=tile, target=target)
    got = [(j.tiles, [r.tolist() for r in j.regions]) for j in plan]
    assert [j.number for j in plan] == list(range(len(plan)))
    assert got == _plan_by_hand(bounds, widths, classes, 25.0, tile, target)


def test_a_plan_packed_wrongly_is_caught(monkeypatch):
    """The broken case: jobs packed to one feature more than asked differ from the plan
    written plainly."""
    from alphafence.fencing import tiles

    rng = np.random.default_rng(8)
    xy = rng.uniform([14.24, 34.99], [14.26, 35.01], size=(200, 2))
    bounds = np.c_[xy, xy + 0.0002]
    args = (bounds, np.zeros(200), np.zeros(200, int), 25.0)
    truth = _plan_by_hand(*args, 0.003, 7)
    got = [(j.tiles, [r.tolist() for r in j.regions]) for j in plan_jobs(*args, 0.003, 7)]
    assert got == truth
    pack = tiles._pack
    monkeypatch.setattr(tiles, "_pack", lambda ends, target: pack(ends, target + 1))
    got = [(j.tiles, [r.tolist() for r in j.regions]) for j in plan_jobs(*args, 0.003, 7)]
    assert got != truth
