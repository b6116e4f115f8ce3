"""Regions, the conservative clusters a large build is split by (fencing/regions.py): the
sweep south to north finds exactly the regions one R-tree over all the extents finds, and
the components found without scipy are scipy's."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.fencing.regions import region_labels


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


def test_large_graph_components_are_scipys():
    """Graphs larger than the ones found without scipy are scipy's components, numbered by
    their smallest node."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    from alphafence.fencing.regions import SMALL_GRAPH, _components

    rng = np.random.default_rng(11)
    n = SMALL_GRAPH + 500
    a, b = rng.integers(0, n - 1, 3000), rng.integers(0, n - 1, 3000)  # the last node alone
    want = connected_components(coo_array((np.ones(3000), (a, b)), shape=(n, n)))[1]
    got = _components(n, a, b)
    assert got.tolist() == want.tolist()
    assert got[0] == 0 and len(np.unique(got)) > 1000  # many components, the first node's first


def test_reach_counts_the_extents_starting_at_or_south_of_an_edge():
    """An extent starting exactly at a chunk's northernmost edge touches it: it is asked."""
    from alphafence.fencing.regions import _reach

    south = np.array([0.0, 1.0, 1.0, 2.0], dtype=np.float32)
    assert [_reach(south, x) for x in (-1.0, 0.0, 1.0, 1.5, 2.0)] == [0, 1, 3, 3, 4]


def test_an_overlap_finer_than_a_32_bit_step_still_joins():
    """Two extents whose grown edges overlap by a nanodegree, each in a chunk of its own: the
    sweep's south edges are rounded down, so the later one is still asked."""
    from alphafence.fencing.regions import M_PER_DEG_LAT, grown_bounds

    south = np.array([14.0, 35.0, 14.001, 35.001])
    north_edge = grown_bounds(south[None], np.zeros(1), 25.0)[0, 3]
    lat = north_edge - 1e-9 + (25.0 + 1.0) / M_PER_DEG_LAT
    bounds = np.array([south, [14.0, lat, 14.001, lat + 0.001]])
    assert grown_bounds(bounds[1:], np.zeros(1), 25.0)[0, 1] < north_edge
    assert region_labels(bounds, np.zeros(2), 25.0, chunk=1).tolist() == [0, 0]


def test_labels_are_32_bit_and_inputs_are_not_copied():
    """Memory: labels in 32 bits for fewer than 2**31 features; 32-bit extents read in place."""
    from alphafence.fencing.regions import floats

    rng = np.random.default_rng(1)
    xy = rng.uniform([14.0, 35.0], [14.01, 35.01], size=(100, 2))
    labels = region_labels(np.c_[xy, xy + 0.0001], np.zeros(100), 25.0)
    assert labels.dtype == np.int32
    for n in (0, 1):  # no sweep at all
        few = region_labels(np.c_[xy, xy + 0.0001][:n], np.zeros(n), 25.0)
        assert few.dtype == np.int32 and few.tolist() == [0] * n
    x32 = np.zeros(3, np.float32)
    assert floats(x32) is x32 and floats(x32.astype(float)).dtype == np.float64
    assert floats(np.arange(3)).dtype == np.float64 and floats([1, 2]).dtype == np.float64


@pytest.mark.parametrize("lat", [0.0, 0.5, 45.0, -60.0, 89.95, -89.99])
def test_extents_grow_by_the_join_at_their_farthest_latitude(lat):
    """Grown by the join, twice the width and a metre: north-south at 110,574 m a degree,
    east-west at 111,320 m a degree times the cosine of the extent's farthest latitude (taken
    no farther than 89.9 degrees)."""
    from alphafence.fencing.regions import grown_bounds

    box = np.array([[14.0, lat, 14.001, lat + 0.0001 * np.sign(lat)]])
    g = grown_bounds(box, np.array([3.0]), 25.0)[0]
    grow = 25.0 + 2 * 3.0 + 1.0
    far = min(max(abs(box[0, 1]), abs(box[0, 3])), 89.9)
    dlon = grow / (111_320.0 * np.cos(np.radians(far)))
    want = [14.0 - dlon, box[0, 1] - grow / 110_574.0, 14.001 + dlon, box[0, 3] + grow / 110_574.0]
    assert np.allclose(g, want, rtol=0, atol=1e-12)
