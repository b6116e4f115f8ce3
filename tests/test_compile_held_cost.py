"""A long fence whose edges bow in lon/lat takes more vertices held as ArduPilot reads it than
its shape has: compile counts each shape at what it takes emitted and chooses again, rather
than leaving less room for everything (which ended, for a 1,000 km strip along the 60th
parallel on a copter, in a budget below zero and a refusal). Shapes that cannot be held at all
are never chosen."""

from __future__ import annotations

import pytest
import shapely

from alphafence.build.pipeline import BuildOptions, build_fences
from alphafence.mavlink.storage import storage_bytes
from alphafence.onboard import compile as compiling

from .test_as_read_properties import (
    KM,
    PROFILES,
    _features,
    _onboard_holds,
    _rules,
    _strip,
    compile_fences,
    read_back,
)


@pytest.mark.parametrize("lat, width_km", [(60.0, 5.0), (-60.0, 20.0)])
def test_a_long_strip_fits_a_copter_and_holds_as_read(lat, width_km, monkeypatch):
    zones = [_strip(20.0, lat, 90.0, 1000 * KM, width_km * KM)]
    rules = _rules("keep_out", 10.0)
    result = build_fences(_features(zones, rules), rules, BuildOptions(method="alpha"))
    records = read_back([f for f in result.fences if f.kind == "keep_out"])
    area = shapely.box(*shapely.union_all([r.geometry for r in records]).bounds)
    recounted = []
    real = compiling._count_as_emitted
    monkeypatch.setattr(compiling, "_count_as_emitted", lambda *a: recounted.append(1) or real(*a))
    onboard = compile_fences(records, area, PROFILES["copter"])
    assert recounted  # the first choice took more than it counted: this is the case
    items = onboard.items
    assert len(items) <= PROFILES["copter"].items
    assert storage_bytes(items) <= PROFILES["copter"].bytes
    _onboard_holds(records, items)  # still contains its fence, as ArduPilot reads it


def test_without_the_recount_the_same_strip_is_refused(monkeypatch):
    """The broken case: costs left as counted, the budget only shrinks, and compile refuses."""
    from alphafence.errors import InputError

    zones = [_strip(20.0, 60.0, 90.0, 1000 * KM, 5.0 * KM)]
    rules = _rules("keep_out", 10.0)
    result = build_fences(_features(zones, rules), rules, BuildOptions(method="alpha"))
    records = read_back([f for f in result.fences if f.kind == "keep_out"])
    area = shapely.box(*shapely.union_all([r.geometry for r in records]).bounds)
    monkeypatch.setattr(compiling, "_count_as_emitted", lambda *a: False)
    with pytest.raises(InputError, match="do not fit a copter"):
        compile_fences(records, area, PROFILES["copter"])
