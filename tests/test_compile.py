"""The fence compiler: onboard fences always contain the keep-out fences they stand for,
fit the vehicle's storage, and pass ArduPilot's own validation rules."""

import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from alphafence.errors import InputError
from alphafence.fencefiles.fence_geojson import FenceRecord, read_fences
from alphafence.fencefiles.qgc_plan import group_polygons
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
)
from alphafence.mavlink.storage import PROFILES, Profile, storage_bytes
from alphafence.onboard.compile import compile_fences

from .ardupilot_model import circle_inradius_m
from .helpers import VerifyFrame


def validate_like_ardupilot(items):
    """Counts consistent, 3..255 vertices, positive radii, known commands."""
    i = 0
    while i < len(items):
        it = items[i]
        assert it.command in (
            POLYGON_INCLUSION,
            POLYGON_EXCLUSION,
            CIRCLE_INCLUSION,
            CIRCLE_EXCLUSION,
            RETURN_POINT,
        )
        if it.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            n = int(it.param1)
            assert 3 <= n <= 255
            assert all(x.command == it.command and int(x.param1) == n for x in items[i : i + n])
            i += n
        else:
            if it.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
                assert it.param1 > 0
            i += 1
        # MAVLink carries 1e-7 degree integers: the compiler emits exactly those
        assert (
            abs(it.lat * 1e7 - round(it.lat * 1e7)) < 1e-6
            and abs(it.lon * 1e7 - round(it.lon * 1e7)) < 1e-6
        )


def onboard_geometry(items, verify, inradius=circle_inradius_m):
    polys, circles = group_polygons(items)
    out = []
    for cmd, pts in polys:
        if cmd == POLYGON_EXCLUSION:
            # read as ArduPilot reads it: straight lon/lat edges (densified before projecting)
            poly = verify.local(shapely.Polygon(np.asarray(pts)))
            assert poly.is_valid, "ArduPilot needs simple polygons"
            out.append(poly)
    disc = []
    for c in circles:
        cx, cy = verify.xy(c.lon, c.lat)
        # the geodesic circle that ArduPilot's own distance surely holds
        disc.append((cx, cy, inradius(c.lon, c.lat, c.param1)))
    return out, disc


def contained(fence_local, polys, discs):
    """Whether the onboard polygons and discs, together, hold the fence: one disc exactly
    (every vertex within it), else the polygons and each disc's inscribed 256-gon (inside
    the disc: a part held across two neighbouring circles is held)."""
    pts = shapely.get_coordinates(fence_local)
    for cx, cy, r in discs:
        if np.all(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) <= r):
            return True
    ang = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
    inscribed = [shapely.Polygon(np.column_stack([cx + r * np.cos(ang), cy + r * np.sin(ang)]))
                 for cx, cy, r in discs]  # fmt: skip
    union = shapely.union_all([*polys, *inscribed]) if polys or discs else shapely.Polygon()
    return union.covers(fence_local)


@st.composite
def fence_sets(draw):
    lon0 = draw(st.floats(-179.9, 179.9))
    lat0 = draw(st.floats(-80, 80))
    frame = LocalFrame(lon0, lat0)
    n = draw(st.integers(1, 14))
    records = []
    for k in range(n):
        cx, cy = draw(st.floats(-3000, 3000)), draw(st.floats(-3000, 3000))
        m = draw(st.integers(3, 60))
        ang = np.sort(
            np.asarray(
                draw(st.lists(st.floats(0, 2 * math.pi), min_size=m, max_size=m, unique=True))
            )
        )
        rad = np.asarray(draw(st.lists(st.floats(20, 400), min_size=m, max_size=m)))
        poly = shapely.Polygon(np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)]))
        if not poly.is_valid or poly.area < 10:
            continue
        records.append(FenceRecord(f"test/{k}", "keep_out", frame.geom_to_wgs84(poly)))
    return lon0, lat0, records


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fence_sets(), st.sampled_from([8, 20, 70]), st.booleans())
def test_compiled_fences_contain_what_they_stand_for(fs, max_items, keep_in):
    lon0, lat0, records = fs
    if not records:
        return
    area = LocalFrame(lon0, lat0).geom_to_wgs84(shapely.box(-500, -500, 500, 500))
    try:
        result = compile_fences(
            records,
            area,
            PROFILES["copter"],
            distance_m=1e6,
            keep_in_m=5000.0 if keep_in else None,
            max_items=max_items,
        )
    except InputError as err:
        assert "do not fit" in str(err)
        return
    items = result.items
    assert len(items) <= max_items and storage_bytes(items) <= 560
    validate_like_ardupilot(items)
    verify = VerifyFrame(lon0, lat0)
    polys, discs = onboard_geometry(items, verify)
    for rec in records:
        local = shapely.make_valid(verify.local(rec.geometry))
        # a ring that projects to a self-touching one is stored part by part
        for part in shapely.get_parts(local):
            assert contained(part, polys, discs), f"{rec.site_id} is not inside the onboard fences"


def test_capacity_edge_matches_ardupilot_storage():
    # one polygon alone: 69 vertices fit 560 bytes (4 + 2 + 8*69 + 1 = 559), 70 do not
    frame = LocalFrame(14.5, 35.9)
    ang = np.linspace(0, 2 * math.pi, 400, endpoint=False)
    star = shapely.Polygon(
        np.column_stack(
            [
                (800 + 300 * np.sin(7 * ang)) * np.cos(ang),
                (800 + 300 * np.sin(7 * ang)) * np.sin(ang),
            ]
        )
    )
    rec = FenceRecord("star", "keep_out", frame.geom_to_wgs84(star))
    result = compile_fences(
        [rec], frame.geom_to_wgs84(shapely.Point(0, 0).buffer(10)), PROFILES["copter"]
    )
    assert storage_bytes(result.items) == 4 + 2 + 8 * 69 + 1 and len(result.items) == 69
    plane = compile_fences(
        [rec], frame.geom_to_wgs84(shapely.Point(0, 0).buffer(10)), PROFILES["plane"]
    )
    assert len(plane.items) == 83  # 672 bytes: 4 + 2 + 8*83 + 1 = 671
    sd = compile_fences(
        [rec], frame.geom_to_wgs84(shapely.Point(0, 0).buffer(10)), PROFILES["sd-fence"]
    )
    assert len(sd.items) <= 255 and sd.loss_m2 < plane.loss_m2 < result.loss_m2


def test_far_fences_are_left_out_and_tiny_budget_merges():
    frame = LocalFrame(14.5, 35.9)
    recs = [
        FenceRecord(f"c{k}", "keep_out", frame.geom_to_wgs84(shapely.Point(300 * k, 0).buffer(40)))
        for k in range(6)
    ]
    recs.append(
        FenceRecord("far", "keep_out", frame.geom_to_wgs84(shapely.Point(50_000, 0).buffer(40)))
    )
    area = frame.geom_to_wgs84(shapely.box(-100, -100, 1600, 100))
    result = compile_fences(recs, area, Profile("tiny", 3, 560), distance_m=1000)
    assert result.dropped == ["far"]
    assert len(result.items) <= 3 and result.merges
    verify = VerifyFrame(14.5, 35.9)
    polys, discs = onboard_geometry(result.items, verify)
    for r in recs[:-1]:
        assert contained(verify.local(r.geometry), polys, discs)


def test_compile_cli_on_the_demo(tmp_path):
    from alphafence.cli import main
    from alphafence.cli.demo import scene_path
    from alphafence.fencefiles.qgc_plan import read_plan_fence
    from alphafence.fencefiles.qgc_wpl import read_waypoints_fence

    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    out = tmp_path / "onboard.plan"
    code = main(
        [
            "compile",
            str(fences),
            "--bbox=-0.58,51.42,-0.52,51.44",
            "--items",
            "40",
            "--keep-in",
            "300",
            "--return-point",
            "51.43,-0.55",
            "-o",
            str(out),
            "--waypoints",
            str(tmp_path / "o.waypoints"),
            "--figure",
            str(tmp_path / "o.png"),
        ]
    )
    assert code == 0
    items = read_plan_fence(out)
    assert len(items) <= 40 and any(i.command == POLYGON_INCLUSION for i in items)
    assert (
        len(read_waypoints_fence(tmp_path / "o.waypoints")) == len(items) + 1
    )  # + the return point
    validate_like_ardupilot(items)
    records = read_fences(fences)
    assert {r.kind for r in records} == {"keep_out", "warning"}


def test_compile_rejects_a_plan_without_positions(tmp_path):
    from alphafence.onboard.compile import operating_area_from_plan

    p = tmp_path / "empty.plan"
    p.write_text('{"fileType": "Plan", "mission": {"items": []}}')
    with pytest.raises(InputError, match="no positions to use"):
        operating_area_from_plan(p)


def test_upload_dry_run_and_missing_area(tmp_path, capsys):
    from alphafence.cli import main
    from alphafence.cli.demo import scene_path

    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    assert main(["upload", str(fences), "--bbox=-0.58,51.42,-0.52,51.44", "--dry-run"]) == 2
    assert "no trusted key" in capsys.readouterr().err  # unsigned fences are refused by default
    assert (
        main(
            [
                "upload",
                str(fences),
                "--bbox=-0.58,51.42,-0.52,51.44",
                "--dry-run",
                "--allow-unsigned",
            ]
        )
        == 0
    )
    assert "nothing sent" in capsys.readouterr().out
    assert main(["upload", str(fences), "--dry-run", "--allow-unsigned"]) == 2
    assert "need an operating area" in capsys.readouterr().err


def test_operating_area_from_a_mission(tmp_path):
    from pathlib import Path

    from alphafence.cli import main
    from alphafence.cli.demo import scene_path
    from alphafence.onboard.compile import operating_area_from_plan

    mission = Path(__file__).resolve().parents[1] / "missions" / "demo-route.plan"
    area, first = operating_area_from_plan(mission)
    assert area.geom_type == "Polygon" and area.covers(shapely.Point(first))
    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    out = tmp_path / "onboard.plan"
    assert (
        main(["compile", str(fences), "--area", str(mission), "--distance", "200", "-o", str(out)])
        == 0
    )
    assert json.loads(out.read_text())["geoFence"]["polygons"]


def test_a_needle_spike_stays_clear_of_every_option():
    """A zero-width spike (a polygon that runs out along a line and back, as the property test
    found): GEOS bevels the padded spike through its tip, so the tip would sit on the onboard
    fence's edge and rounding could cut it off; every option must stand clear of it."""
    from alphafence.onboard.options import PAD_M, piece_options

    needle = shapely.Polygon(
        [
            (-1042.3519843136253, 97.9095958535494),
            (-1296.4487106397955, 97.90959585354915),
            (-1296.4487106397955, 97.90959585354915),
            (-1296.4487106397955, 97.90959585354915),
            (-1296.4487107403434, 97.91159585354586),
            (-1307.1337232185426, 115.60792937228356),
            (-1336.2837426193657, 95.3461008968039),
            (-1355.667327891366, 52.501446135073124),
            (-1285.2971064179528, -17.976458330811642),
            (-1240.2906754678288, -31.318704757442546),
            (-1304.3711860623264, 81.96803382013795),
            (-1176.443930191033, -11.595365142902155),
            (-1115.6138304274286, -19.3807073379472),
            (-1029.3930620288234, 29.99032445790397),
            (-1097.434007255783, 97.90959585354857),
        ]
    )  # found by hypothesis: the edge into the first vertex runs out to it and back
    assert needle.is_valid
    for opt in piece_options(needle, False, 255):
        assert opt.local.covers(needle)
        assert shapely.distance(opt.local.exterior, needle.exterior) >= 0.9 * PAD_M, opt.label


def test_the_containment_check_takes_neighbouring_circles_together_and_sees_a_gap():
    """The check the onboard properties use: a sliver held by two overlapping circles is held;
    pull them apart, or move the sliver out, and it is not (the broken cases)."""
    sliver = shapely.box(0.0, -0.01, 30.0, 0.01)
    assert contained(sliver, [], [(8.0, 0.0, 9.0), (22.0, 0.0, 9.0)])
    assert not contained(sliver, [], [(8.0, 0.0, 9.0), (24.0, 0.0, 6.0)])  # a gap at 17-18 m
    assert not contained(shapely.box(0.0, 5.0, 30.0, 9.5), [], [(8.0, 0.0, 9.0), (22.0, 0.0, 9.0)])
    assert contained(sliver, [shapely.box(-1, -1, 16, 1)], [(22.0, 0.0, 9.0)])
