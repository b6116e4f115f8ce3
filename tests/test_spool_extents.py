"""The spool keeps each feature's extent and width in 32-bit floats rounded outwards (half the
memory of a large build's planning), so the extents it plans from still hold the features:
the regions found from them are the exact regions or joins of them, never splits."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from alphafence.fencing import regions
from alphafence.fencing.regions import outward, region_labels
from alphafence.fencing.spool import Spool
from alphafence.zones.features import Feature
from alphafence.zones.rules import load_rules

RULE = load_rules().rules[0]
coords = st.floats(-179.99, 179.99, allow_nan=False, allow_subnormal=False)


def _spooled(boxes, widths):
    features = [Feature(g, {}, f"way/{i}", "test", RULE) for i, g in enumerate(boxes)]
    spool = Spool()
    spool.add(features, widths, [0] * len(features))
    return spool


@settings(max_examples=200, deadline=None)
@given(
    xs=arrays(float, (12, 2), elements=coords),
    ys=arrays(float, (12, 2), elements=st.floats(-89.9, 89.9, allow_subnormal=False)),
    widths=arrays(float, 12, elements=st.floats(0, 5000, allow_subnormal=False)),
)
def test_the_spooled_extents_hold_the_features(xs, ys, widths):
    xs.sort(axis=1)
    ys.sort(axis=1)
    boxes = shapely.box(xs[:, 0], ys[:, 0], xs[:, 1], ys[:, 1])
    with _spooled(boxes, widths) as spool:
        kept, true = spool.bounds.astype(float), shapely.bounds(boxes)
        assert spool.bounds.dtype == np.float32 and spool.widths.dtype == np.float32
        assert np.all(kept[:, :2] <= true[:, :2]) and np.all(kept[:, 2:] >= true[:, 2:])
        assert np.all(spool.widths.astype(float) >= widths)
        # and no looser than one step of a 32-bit float
        step = np.spacing(np.abs(true).astype(np.float32)).astype(float)
        assert np.all(np.abs(kept - true) <= step)


def test_extents_rounded_to_nearest_are_caught(monkeypatch):
    """The broken case: rounding to the nearest 32-bit float cuts into some extents."""
    from alphafence.fencing import spool as spool_module

    rng = np.random.default_rng(2)
    lo = rng.uniform([14.0, 35.0], [14.5, 35.5], size=(200, 2))
    boxes = shapely.box(*lo.T, *(lo + 0.001).T)
    nearest = lambda values, up: np.asarray(values, dtype=np.float32)  # noqa: E731
    monkeypatch.setattr(spool_module, "outward", nearest)
    with _spooled(boxes, np.zeros(200)) as spool:
        kept, true = spool.bounds.astype(float), shapely.bounds(boxes)
        assert not (np.all(kept[:, :2] <= true[:, :2]) and np.all(kept[:, 2:] >= true[:, 2:]))


def _chain(rng, n):
    """Boxes in a row near the antimeridian (a 32-bit float's step there is about a metre)
    whose grown extents overlap by less than that step: one region, exactly."""
    lat = 60.0
    lon, boxes = 179.0, []
    for _ in range(n):
        w = rng.uniform(0.0001, 0.0005)
        box = np.array([[lon, lat, lon + w, lat + 0.0002]])
        boxes.append(box[0])
        dlon = regions.grown_bounds(box, np.zeros(1), 25.0)[0, 2] - (lon + w)
        lon = lon + w + 2 * dlon - rng.uniform(0, 1e-5)
    return np.array(boxes)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 60), seed=st.integers(0, 2**32 - 1))
def test_regions_from_the_rounded_extents_never_split_a_region(n, seed):
    """Regions from the spool's rounded extents join exact regions, never split one."""
    bounds = _chain(np.random.default_rng(seed), n)
    exact = region_labels(bounds, np.zeros(n), 25.0)
    with _spooled(shapely.box(*bounds.T), np.zeros(n)) as spool:
        rounded = region_labels(spool.bounds, spool.widths, 25.0)
    for label in np.unique(exact):  # every exact region lies inside one rounded region
        assert len(np.unique(rounded[exact == label])) == 1


def test_regions_from_extents_rounded_to_nearest_split(monkeypatch):
    """The broken case: extents rounded to the nearest 32-bit float split the chain."""
    from alphafence.fencing import spool as spool_module

    bounds = _chain(np.random.default_rng(6), 60)
    assert len(set(region_labels(bounds, np.zeros(60), 25.0).tolist())) == 1
    monkeypatch.setattr(spool_module, "outward", lambda v, up: np.asarray(v, dtype=np.float32))
    with _spooled(shapely.box(*bounds.T), np.zeros(60)) as spool:
        assert len(set(region_labels(spool.bounds, spool.widths, 25.0).tolist())) > 1


def test_a_south_edge_rounded_up_is_caught(monkeypatch):
    """The broken case: the sweep's south edges rounded up (towards the extents) miss pairs
    an extent's southern edge reaches, and the regions split."""
    from tests.test_regions import _regions_at_once

    rng = np.random.default_rng(4)
    lon = rng.uniform(14.0, 14.01, 400)
    lat = 35.0 + np.sort(rng.uniform(0, 0.02, 400))
    bounds = np.c_[lon, lat, lon + 0.0003, lat + 0.0003]
    zeros, one = np.zeros(400), np.zeros(400, int)
    truth = _regions_at_once(bounds, zeros, one, 25.0).tolist()
    assert region_labels(bounds, zeros, 25.0, classes=one, chunk=8).tolist() == truth
    real = regions.outward
    monkeypatch.setattr(regions, "outward", lambda v, up: real(np.asarray(v) + 5e-4, up=True))
    assert region_labels(bounds, zeros, 25.0, classes=one, chunk=8).tolist() != truth


def test_values_a_32_bit_float_holds_are_kept_as_they_are():
    """Rounded outwards only when rounding is needed: 20 m stays 20 m, 0.5 degrees stays."""
    exact = np.array([20.0, 0.5, -14.25, 0.0, 1e-3])
    for up in (True, False):
        kept = outward(exact, up=up).astype(float)
        assert kept[:4].tolist() == exact[:4].tolist()
        assert (kept[4] > exact[4]) if up else (kept[4] < exact[4])  # 0.001 is not one
