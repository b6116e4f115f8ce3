"""The monitor's onboard layer: the fence the vehicle itself enforces, checked beside the
full-resolution fences. An onboard circle larger than the real fence raises WARNING and
IMMINENT before the real fence would, names its item and says it is the onboard fence only;
with enforce the vehicle is stopped before it. An onboard fence that is the real fence (to
the 1e-7 degree) changes nothing. Unreadable fences are events."""

from __future__ import annotations

import math

import pytest
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.predict import stopping_distance
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    RETURN_POINT,
    FenceItem,
    polygon_lonlat,
)
from alphafence.monitor.engine import Engine, Sample
from alphafence.monitor.events import alert_text
from alphafence.monitor.options import MonitorOptions
from alphafence.onboard.decode import decode_fence

FRAME = LocalFrame(14.486, 35.891)
SQUARE = shapely.box(-50, 300, 50, 400)  # the real keep-out fence, 300 m north
CIRCLE_R = 150.0  # an onboard circle around it: its edge 200 m north
CIRCLE_EDGE = 350.0 - CIRCLE_R
SPEED = 10.0


def full_fences():
    return FenceSet(
        [FenceRecord("hospital/way/7", "keep_out", FRAME.geom_to_wgs84(SQUARE))], frame=FRAME
    )


def circle_item(x, y, r, command=CIRCLE_EXCLUSION):
    lon, lat = FRAME.to_wgs84(x, y)
    return FenceItem(command, r, float(lon), float(lat))


def square_items(poly=SQUARE):
    pts = polygon_lonlat(FRAME.geom_to_wgs84(poly))
    return [FenceItem(POLYGON_EXCLUSION, float(len(pts)), lon, lat) for lon, lat in pts]


def return_point():
    lon, lat = FRAME.to_wgs84(0.0, -20.0)
    return FenceItem(RETURN_POINT, 0.0, float(lon), float(lat))


def north_run(speed=SPEED, dt=0.1, seconds=45, start=0.0):
    for k in range(int(seconds / dt)):
        lon, lat = FRAME.to_wgs84(0.0, start + speed * k * dt)
        yield Sample(k * dt, float(lat), float(lon), 20.0, vn=speed, mode="GUIDED", armed=True)


def y_of(event):
    return float(FRAME.to_local(event["lon"], event["lat"])[1])


def fly(engine, samples, until_level=None):
    events = []
    for s in samples:
        events += engine.step(s)
        if until_level and any(e.get("level") == until_level for e in events):
            break
    return events


def levels(events):
    return {e["level"]: e for e in events if e["event"] == "level"}


def test_an_onboard_circle_over_the_real_fence_raises_the_alerts_before_it():
    engine = Engine(full_fences(), MonitorOptions())
    loaded = engine.load_onboard([return_point(), circle_item(0, 350, CIRCLE_R)], t=0.0)
    assert [e["event"] for e in loaded] == ["onboard_fence"]
    assert loaded[0]["items"] == 2 and loaded[0]["fences"] == {"exclusion circle": 1}
    # what the circle forbids beyond the real square
    beyond = math.pi * CIRCLE_R**2 - SQUARE.area
    assert loaded[0]["forbidden_beyond_m2"] == pytest.approx(beyond, rel=0.01)

    found = levels(fly(engine, north_run()))
    warning, imminent, breach = found["WARNING"], found["IMMINENT"], found["BREACH"]
    stop = stopping_distance(SPEED)
    # each at the onboard circle's edge, 100 m before the real fence would raise it
    assert y_of(warning) == pytest.approx(CIRCLE_EDGE - SPEED * 15, abs=1.1)
    assert y_of(imminent) == pytest.approx(CIRCLE_EDGE - stop, abs=1.1)
    assert y_of(breach) == pytest.approx(CIRCLE_EDGE, abs=1.1)
    for e in (warning, imminent, breach):
        assert e["fence"] == "onboard exclusion circle 1 (item 1)", e
        assert e["onboard"] == "excl circle 1 #1" and e["items"] == [1, 1]
        assert e["onboard_only"] is True
        assert "the full-resolution fences allow this airspace" in e["reason"]
        text = alert_text(e)
        assert text.startswith(f"AF {e['level']} ONBOARD ONLY excl circle 1 #1") and len(text) <= 50
    assert imminent["time_to_breach_s"] == pytest.approx(stop / SPEED, abs=0.15)
    assert imminent["stopping_m"] == pytest.approx(stop, abs=0.01)

    # without the onboard layer the same flight alerts only at the real fence, 100 m later
    plain = levels(fly(Engine(full_fences(), MonitorOptions()), north_run()))
    assert y_of(plain["IMMINENT"]) - y_of(imminent) == pytest.approx(300 - CIRCLE_EDGE, abs=1.1)
    assert plain["IMMINENT"]["fence"] == "hospital/way/7" and not plain["IMMINENT"]["onboard_only"]


def test_with_enforce_the_vehicle_is_stopped_before_the_onboard_fence():
    engine = Engine(full_fences(), MonitorOptions(enforce=True))
    engine.load_onboard([circle_item(0, 350, CIRCLE_R)])
    events = fly(engine, north_run(), until_level="IMMINENT")
    imminent = levels(events)["IMMINENT"]
    action = [e for e in events if e["event"] == "action"]
    assert [a["action"] for a in action] == ["brake"] and action[0]["time"] == imminent["time"]
    # the brake comes at the first position from which braking (the engine's own model) would
    # not end before the onboard circle's edge as ArduPilot measures it (its own distance:
    # 0.3 % long north-south here, so its edge lies half a metre north of the geodesic one)
    (onboard,) = decode_fence([circle_item(0, 350, CIRCLE_R)])
    edge = float(FRAME.geom_to_local(onboard.geometry()).bounds[1])
    assert CIRCLE_EDGE < edge < CIRCLE_EDGE + 1.0
    step = SPEED * 0.1  # north_run's positions are 0.1 s apart
    stop = stopping_distance(SPEED)
    assert y_of(imminent) - step + stop < edge <= y_of(imminent) + stop


def test_a_reroute_cannot_avoid_a_fence_the_planner_does_not_know_so_it_brakes():
    options = MonitorOptions(enforce=True, imminent_action="reroute")
    engine = Engine(full_fences(), options)
    engine.load_onboard([circle_item(0, 350, CIRCLE_R)])
    events = fly(engine, north_run(), until_level="IMMINENT")
    assert [e["action"] for e in events if e["event"] == "action"] == ["brake"]


def test_an_onboard_fence_that_is_the_real_fence_changes_nothing():
    # (positions 0.37 m off the metre grid: not exactly on the edge, which rounding moves)
    plain = fly(Engine(full_fences(), MonitorOptions(enforce=True)), north_run(start=0.37))
    engine = Engine(full_fences(), MonitorOptions(enforce=True))
    loaded = engine.load_onboard(square_items())  # rounded to 1e-7 degrees
    assert loaded[0]["fences"] == {"exclusion polygon": 1} and loaded[0]["forbidden_beyond_m2"] == 0
    events = fly(engine, north_run(start=0.37))
    key = lambda e: (e["time"], e["event"], e.get("level"), e.get("action"))  # noqa: E731
    assert [key(e) for e in events] == [key(e) for e in plain]
    for e in (e for e in events if e["event"] == "level"):
        assert e["fence"] == "hospital/way/7" and e["onboard_only"] is False


def test_a_slightly_larger_onboard_polygon_names_the_real_fence():
    # an outward simplification 1 m out: the onboard fence raises the level first, but it is the
    # real fence there, not airspace the full-resolution fences allow
    engine = Engine(full_fences(), MonitorOptions())
    engine.load_onboard(square_items(shapely.box(-51, 299, 51, 401)))
    found = levels(fly(engine, north_run()))
    for e in found.values():
        assert e["fence"] == "hospital/way/7" and e["onboard_only"] is False, e
    assert found["IMMINENT"]["onboard"] == "excl poly 1 #0-3"
    assert alert_text(found["IMMINENT"]).startswith("AF IMMINENT hospital/way/7")


def test_leaving_an_onboard_inclusion_is_predicted_like_a_keep_out_fence():
    engine = Engine(full_fences(), MonitorOptions(enforce=True))
    # an inclusion circle of 150 m around the start; the real square lies beyond it
    engine.load_onboard([circle_item(0, 0, 150.0, CIRCLE_INCLUSION)])
    events = fly(engine, north_run(seconds=20))
    found = levels(events)
    stop = stopping_distance(SPEED)
    assert y_of(found["WARNING"]) < y_of(found["IMMINENT"]) < y_of(found["BREACH"])
    # the inclusion's polygon lies inside the circle (by < 0.2 m at 150 m): never later
    assert y_of(found["IMMINENT"]) == pytest.approx(150 - stop, abs=1.3)
    assert y_of(found["BREACH"]) == pytest.approx(150, abs=1.2)
    for e in found.values():
        assert e["fence"] == "onboard inclusion circle 1 (item 0)" and e["onboard_only"], e
    assert [e["action"] for e in events if e["event"] == "action"] == ["brake", "rtl"]


def test_the_onboard_layer_holds_at_every_altitude():
    # ArduPilot's polygons and circles have no altitude band: the full-resolution fence does
    full = FenceSet(
        [FenceRecord("ctr/1", "keep_out", FRAME.geom_to_wgs84(SQUARE), alt_max_m=10.0)],
        frame=FRAME,
    )
    engine = Engine(full, MonitorOptions())
    engine.load_onboard(square_items())
    found = levels(fly(engine, north_run()))  # at 20 m: above the real fence
    assert found["BREACH"]["onboard_only"] and found["BREACH"]["fence"].startswith("onboard")


def test_unreadable_or_empty_fences_are_events_and_the_previous_layer_is_kept():
    engine = Engine(full_fences(), MonitorOptions())
    assert engine.load_onboard([circle_item(0, 350, CIRCLE_R)])[0]["event"] == "onboard_fence"
    layer = engine.onboard
    broken = square_items()[:3]  # a polygon of 4 vertices with 3 items
    failed = engine.load_onboard(broken, cause="upload")
    assert failed[0]["event"] == "onboard_failed" and failed[0]["cause"] == "upload"
    assert "item 0: a polygon of 4 vertices has only 3 items" in failed[0]["error"]
    assert failed[0]["kept"] == "the previous onboard fence (1 items)"
    assert engine.onboard is layer and alert_text(failed[0]) == "AF onboard fence unreadable"
    lost = engine.onboard_unreadable("download failed: timeout")
    assert lost[0]["error"] == "download failed: timeout" and engine.onboard is layer

    none = engine.load_onboard([return_point()])
    assert none[0]["event"] == "onboard_none" and engine.onboard is None
    assert alert_text(none[0]) == "AF no onboard fence"
    assert engine.onboard_unreadable("x")[0]["kept"].startswith("no onboard fence")
    # with no layer the engine checks the full-resolution fences as before
    assert levels(fly(engine, north_run()))["IMMINENT"]["fence"] == "hospital/way/7"


def test_the_option_is_checked():
    from alphafence.errors import InputError

    assert MonitorOptions().onboard == "watch"
    with pytest.raises(InputError, match="onboard: 'on': must be one of watch, rolling, off"):
        MonitorOptions(onboard="on")


def test_the_cli_passes_the_onboard_mode(tmp_path, monkeypatch, capsys):
    import json
    from types import SimpleNamespace

    from alphafence.cli import main

    seen = []

    async def run_monitor(url, fences, options, *args, **kwargs):
        seen.append(options.onboard)
        return SimpleNamespace(engine=SimpleNamespace(checks=0))

    monkeypatch.setattr("alphafence.monitor.run.run_monitor", run_monitor)
    feature = {
        "type": "Feature",
        "properties": {"site_id": "hospital/way/7", "kind": "keep_out"},
        "geometry": shapely.geometry.mapping(FRAME.geom_to_wgs84(SQUARE)),
    }
    path = tmp_path / "fences.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [feature]}))
    argv = [
        "monitor",
        "--connect",
        "udpin://127.0.0.1:1",
        "--fences",
        str(path),
        "--allow-unsigned",
    ]
    assert main(argv) == 0 and main(argv + ["--onboard", "off"]) == 0
    assert seen == ["watch", "off"]
    with pytest.raises(SystemExit) as exit_:
        main(argv + ["--onboard", "sometimes"])
    assert exit_.value.code == 2 and "--onboard" in capsys.readouterr().err
