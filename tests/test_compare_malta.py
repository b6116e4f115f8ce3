"""The paper's evaluation on real OpenStreetMap data (Malta 2018)."""

import pytest

from alphafence.fencing.compare import compare_methods
from alphafence.fencing.fences import contains_with_margin
from alphafence.fencing.pipeline import BuildOptions, build_fences


@pytest.fixture(scope="module")
def comparison(malta_db, rules):
    return compare_methods(malta_db.features, rules, ["alpha", "polygon", "circle", "exact"])


def test_every_method_contains_all_restricted_area(comparison):
    for s in comparison.stats:
        assert s.containment_pct == pytest.approx(100.0, abs=1e-6), s.method


def test_alpha_is_tighter_than_polygon_and_circle(comparison):
    st = {s.method: s for s in comparison.stats}
    assert st["exact"].excess <= st["alpha"].excess < st["polygon"].excess < st["circle"].excess
    assert st["alpha"].vertices_p95 <= 32 and st["exact"].vertices_p95 > 32


def test_every_malta_fence_holds_its_margin(malta_db, rules):
    result = build_fences(malta_db.features, rules, BuildOptions())
    sites = {s.site_id: s for s in result.sites}
    assert len(sites) > 250
    for f in result.fences:
        assert contains_with_margin(f.local, f.circle, sites[f.site_id].geometry, f.margin_m), (
            f.site_id
        )
        assert not f.repaired, f.site_id


def test_campus_sites_merge_features(malta_db, rules):
    result = build_fences(malta_db.features, rules, BuildOptions())
    multi = [s for s in result.sites if len(s.sources) > 1]
    assert multi and all(len({f.category for f in s.features}) == 1 for s in multi)
