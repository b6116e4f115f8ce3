"""The cold-code bench's stages are the monitor's own: pymavlink decodes the position SITL's
Malta home sends, and the engine checks it against the fences (bench/cold_bench.py)."""

from __future__ import annotations

import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.sitl.homes import resolve_home
from bench import cold_bench


def _fences_near_home(x0):
    home = resolve_home(cold_bench.HOME)
    frame = LocalFrame(home.lon, home.lat)
    square = frame.geom_to_wgs84(shapely.box(x0, -50, x0 + 100, 50))  # x0 m east of home
    return home, FenceSet([FenceRecord("east", "keep_out", square)])


def test_stages_decode_and_step_the_home_position():
    home, fences = _fences_near_home(200.0)
    fences.index()
    nothing, bare, decode, to_local, step = cold_bench.stages(fences).values()
    assert nothing() is None
    (msg,) = decode()
    assert bare() == tuple(msg.to_dict()[k] for k in msg.fieldnames)  # the same fields
    assert msg.get_type() == "GLOBAL_POSITION_INT"
    assert abs(msg.lat / 1e7 - home.lat) < 1e-7 and abs(msg.lon / 1e7 - home.lon) < 1e-7
    home_m = shapely.Point(to_local())  # in the fences' metres: 200 m west of the square
    assert abs(shapely.distance(home_m, fences.local[0]) - 200.0) < 0.01
    assert step() == [] and step() == []  # clear of the square: no event


def test_the_step_checks_the_fences():
    _, fences = _fences_near_home(-50.0)  # home inside the square
    *_, step = cold_bench.stages(fences).values()
    assert [e["level"] for e in step() if e["event"] == "level"] == ["BREACH"]


def test_cpu_us_times_each_call():
    calls = []
    us = cold_bench.cpu_us(lambda: calls.append(sum(range(2000))), 0.001, repeat=5)
    assert len(calls) == 10 + 5 and us > 0.0
