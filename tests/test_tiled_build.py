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


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(1, 80),
    edges=st.lists(st.tuples(st.integers(0, 79), st.integers(0, 79)), max_size=120),
)
def test_small_graph_components_are_scipys(n, edges):
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    from alphafence.fencing.sites import _components

    a = np.array([e[0] % n for e in edges], dtype=np.int64)
    b = np.array([e[1] % n for e in edges], dtype=np.int64)
    graph = coo_array((np.ones(len(a)), (a, b)), shape=(n, n))
    assert _components(n, a, b).tolist() == connected_components(graph, directed=False)[1].tolist()


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1000, 4096), seed=st.integers(0, 2**32 - 1), chords=st.integers(0, 50))
def test_long_path_components_are_scipys(n, seed, chords):
    """Graphs as large as the ones found without scipy, at their longest: a path through
    the nodes in a random order, cut in places, with a few chords."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    from alphafence.fencing.regions import SMALL_GRAPH
    from alphafence.fencing.sites import _components

    rng = np.random.default_rng(seed)
    n = min(n, SMALL_GRAPH)
    order = rng.permutation(n)
    keep = rng.random(n - 1) > 0.01
    a = np.concatenate([order[:-1][keep], rng.integers(0, n, chords)])
    b = np.concatenate([order[1:][keep], rng.integers(0, n, chords)])
    graph = coo_array((np.ones(len(a)), (a, b)), shape=(n, n))
    assert _components(n, a, b).tolist() == connected_components(graph, directed=False)[1].tolist()


def _regions_at_once(bounds, widths, classes, join_m):
    """Regions as one R-tree over every grown extent finds them: the pairs that meet, of one
    class, joined by scipy (written here apart from the kit's sweep)."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    n = len(bounds)
    lat = np.clip(np.maximum(np.abs(bounds[:, 1]), np.abs(bounds[:, 3])), 0, 89.9)
    grow = join_m + 2 * widths + 1.0
    dlat, dlon = grow / 110_574.0, grow / (111_320.0 * np.cos(np.radians(lat)))
    boxes = shapely.box(bounds[:, 0] - dlon, bounds[:, 1] - dlat, bounds[:, 2] + dlon,
                        bounds[:, 3] + dlat)  # fmt: skip
    a, b = shapely.STRtree(boxes).query(boxes, predicate="intersects")
    same = classes[a] == classes[b]
    graph = coo_array((np.ones(int(same.sum())), (a[same], b[same])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(2, 400),
    seed=st.integers(0, 2**32 - 1),
    chunk=st.integers(1, 64),
    tall=st.integers(0, 5),
    kinds=st.integers(1, 3),
)
def test_the_sweep_finds_the_regions_one_tree_finds(n, seed, chunk, tall, kinds):
    """Regions found chunk by chunk, south to north (the planet's way, in constant memory), are
    those one R-tree over all the extents finds, numbered by their first feature: small chunks,
    extents that reach across many chunks, touching edges, several classes and widths."""
    from alphafence.fencing.regions import region_labels

    rng = np.random.default_rng(seed)
    xy = rng.uniform([14.0, 35.0], [14.05, 35.05], size=(n, 2))
    size = rng.uniform(0, 0.002, size=(n, 2))
    size[rng.integers(0, n, tall), 1] = rng.uniform(0.01, 0.05, tall)  # long north-south
    bounds = np.round(np.c_[xy, xy + size], 4)  # rounded: some extents share edges
    widths = rng.choice([0.0, 5.0, 20.0], n)
    classes = rng.integers(0, kinds, n)
    got = region_labels(bounds, widths, 25.0, classes=classes, chunk=chunk)
    assert got.tolist() == _regions_at_once(bounds, widths, classes, 25.0).tolist()


def test_a_sweep_that_misses_a_pair_is_caught(monkeypatch):
    """The broken case: a sweep that asks only each chunk's own extents splits regions that
    meet across a chunk's edge, and the comparison above sees it."""
    from alphafence.fencing import regions

    rng = np.random.default_rng(3)
    xy = rng.uniform([14.0, 35.0], [14.01, 35.01], size=(300, 2))
    bounds = np.c_[xy, xy + 0.0004]
    zeros, one = np.zeros(300), np.zeros(300, int)
    truth = _regions_at_once(bounds, zeros, one, 25.0).tolist()
    assert regions.region_labels(bounds, zeros, 25.0, classes=one, chunk=16).tolist() == truth
    monkeypatch.setattr(regions, "_reach", lambda south, north: 0)  # later extents never asked
    assert regions.region_labels(bounds, zeros, 25.0, classes=one, chunk=16).tolist() != truth
