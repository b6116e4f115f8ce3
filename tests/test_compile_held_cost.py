"""A long fence whose edges bow in lon/lat takes more vertices held as ArduPilot reads it than
its shape has: compile counts each shape at what it takes emitted and chooses again, rather
than leaving less room for everything (which ended, for a 1,000 km strip along the 60th
parallel on a copter, in a budget below zero and a refusal). Shapes that cannot be held at all
are never chosen."""

from __future__ import annotations

import pytest
import shapely

from alphafence.fencing.pipeline import BuildOptions, build_fences
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


def test_a_fence_read_as_polygons_and_spikes_is_stored_whole():
    """A fence file's polygon whose outline crosses itself and runs out to vertices and
    straight back (read as a MultiPolygon and the spikes' lines) is stored, spikes and all: it
    was once left out, the onboard fence holding none of it."""
    from alphafence.fencefiles.fence_geojson import FenceRecord

    record = FenceRecord("zone/spiked", "keep_out", shapely.from_wkt(SPIKED))
    onboard = compile_fences([record], shapely.Point(0.0, 51.9104733), PROFILES["copter"])
    assert [p.sources for p in onboard.pieces] == [["zone/spiked"]]
    _onboard_holds([record], onboard.items)  # every sample of its outline, spikes too


SPIKED = (  # a fence found by the onboard property test: two lobes and spikes, 58 vertices
    "POLYGON ((0.0002906346 51.9104732833, 0.0002906346 51.9104732833, 0.0002906346 "
    "51.9104732833, 0.0002906346 51.9104732833, 0.0002906346 51.9104732833, 0.0012933239 "
    "51.9104732766, 0.0008137768 51.9104732809, 0.0002906346 51.9104732833, 0.0058126917 "
    "51.9104731402, 0.0002906346 51.9104732833, 0.000305164 51.9104740206, 0.0002883671 "
    "51.9104956936, 0.0002855409 51.9105067893, 0.0002815997 51.9105177542, 0.0002550563 "
    "51.9105594602, 0.0002356945 51.9105784547, 0.0002126547 51.9105958081, 0.0001998658 "
    "51.9106037836, 0.0001862964 51.9106112495, 0.0001719996 51.9106181766, 0.0001645957 "
    "51.9106214296, 0.0001570311 51.910624538, 0.0001545963 51.9106254943, 9.1643931726e-5 "
    "51.9106438636, 8.6296688471e-5 51.9106449271, 5.6542514156e-5 51.9106495992, "
    "2.0558759253e-5 51.9106525834, -1.5745812026e-5 51.9106527697, -5.1804672249e-5 "
    "51.9106501551, -5.7576839502e-5 51.9106494711, -6.044772505e-5 51.9106491029, "
    "-7.7900557681e-5 51.9106464565, -7.9861664986e-5 51.9106461144, -8.7055128415e-5 "
    "51.9106447806, -0.0001183869 51.9106374453, -0.0001209471 51.9106367298, -0.0001293065 "
    "51.9106342633, -0.0001825695 51.9106131422, -0.0002093384 51.9105979734, -0.0002213953 "
    "51.9105897355, -0.0002299237 51.9105832324, -0.0037605118 51.9122105655, -0.0002527094 "
    "51.9105620656, -0.0002686346 51.9105418869, -0.0002877262 51.9104986497, -0.0002885421 "
    "51.910494815, -0.0002903 51.9104646615, -0.0002889283 51.9104538353, -0.0002721663 "
    "51.9104102301, -0.0002384824 51.9103705453, -0.0002070248 51.9103471255, -0.0001899709 "
    "51.9103372483, -6.1264310985e-5 51.9102975726, 8.244172646e-5 51.910300917, 0.0002059634 "
    "51.9103464626, 0.0003488229 51.910410502, 0.0028902181 51.9104139068, 0.0002906346 "
    "51.9104732833))"
)
