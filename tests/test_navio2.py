"""Full-resolution onboard fences in file-backed storage (``--profile navio2``, BRD_SD_FENCE):
the profile's sizes, the compiled fences (exact up to 255 vertices, simplified outward beyond,
always containing what they stand for), and the upload's storage check, ``--reboot`` and the
download guard against the scripted ArduPilot peer (tests/fake_vehicle.py)."""

from __future__ import annotations

import asyncio
import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.fencefiles import qgc_plan
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencefiles.qgc_plan import group_polygons
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem
from alphafence.mavlink.storage import (
    PROFILES,
    file_storage_bytes,
    navio2_profile,
    sd_fence_kb_needed,
    storage_bytes,
)
from alphafence.onboard.compile import compile_fences
from alphafence.onboard.options import PAD_M
from alphafence.vehicle.fence_transfer import (
    FenceTransferError,
    download_fence,
    same_items,
    upload_fence,
)
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.reboot import RebootError, reboot_vehicle
from alphafence.vehicle.sd_fence import kb_needed
from tests.fake_vehicle import FakeVehicle

from .helpers import VerifyFrame

# ------------------------------------------------------------------ the profile


@pytest.mark.parametrize("kb", [1, 2, 8, 32, 63, 64])
def test_profile_is_what_ardupilot_attaches(kb):
    # StorageAccess::attach_file: min(kb * 1024, 0xFFFF) bytes; max_items = size / 8
    p = navio2_profile(kb)
    size = min(kb * 1024, 65535)
    assert (p.bytes, p.items, p.sd_fence_kb, p.max_polygon_vertices) == (size, size // 8, kb, 255)
    assert p.file_backed and not PROFILES["copter"].file_backed
    assert PROFILES["navio2"] == navio2_profile(64)


@pytest.mark.parametrize("kb", [0, 65, -1])
def test_profile_refuses_sizes_ardupilot_does_not_have(kb):
    with pytest.raises(ValueError, match="1 to 64"):
        navio2_profile(kb)


polygon_sizes = st.lists(st.integers(3, 255), min_size=1, max_size=40)


@given(polygon_sizes, st.integers(0, 300))
def test_kb_needed_is_the_least_that_holds_the_fence(sizes, circles):
    items = [FenceItem(POLYGON_EXCLUSION, float(n), 14.5, 35.9) for n in sizes for _ in range(n)]
    items += [FenceItem(5004, 30.0, 14.5, 35.9)] * circles
    kb = sd_fence_kb_needed(items)
    need = max(storage_bytes(items), 8 * len(items))
    assert file_storage_bytes(kb) >= need
    assert kb == 1 or file_storage_bytes(kb - 1) < need
    board = PROFILES["copter"]
    fits_board = len(items) <= board.items and storage_bytes(items) <= board.bytes
    assert kb_needed(items) == (0 if fits_board else kb)


# ------------------------------------------------------------------ the compiled fences


def wavy(n, cx, cy, r, seed, noise=2.0):
    """A smooth-ish polygon of n vertices (a site at full resolution)."""
    rng = np.random.default_rng(seed)
    ang = np.linspace(0, 2 * math.pi, n, endpoint=False)
    rad = r * (1 + 0.25 * np.sin(3 * ang + seed) + 0.1 * np.cos(7 * ang)) + rng.uniform(
        -noise, noise, n
    )
    return shapely.Polygon(np.column_stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang)]))


def onboard_shapes(items, verify):
    """(exclusion polygons, inclusion polygons, circles, each exclusion's vertex count) of
    items, in the verify frame, each polygon's edges read as straight lon/lat lines (as
    ArduPilot reads them)."""
    polys, circles = group_polygons(items)
    out, keep_in, counts = [], [], []
    for cmd, pts in polys:
        pts = np.asarray(pts)
        poly = verify.local(shapely.Polygon(pts))
        assert poly.is_valid and 3 <= len(pts) <= 255
        (out if cmd == POLYGON_EXCLUSION else keep_in).append(poly)
        if cmd == POLYGON_EXCLUSION:
            counts.append(len(pts))
    discs = [(*verify.xy(c.lon, c.lat), c.param1) for c in circles]
    return out, keep_in, discs, counts


@st.composite
def full_resolution_sets(draw):
    lon0, lat0 = draw(st.floats(-179, 179)), draw(st.floats(-75, 75))
    frame = LocalFrame(lon0, lat0)
    records = []
    for k in range(draw(st.integers(1, 5))):
        n = draw(st.sampled_from([3, 5, 12, 40, 120, 255, 256, 400, 700]))
        cx, cy = k * 900.0 - 1800.0, draw(st.floats(-500, 500))
        poly = wavy(n, cx, cy, draw(st.floats(60, 350)), draw(st.integers(0, 10_000)))
        if poly.is_valid:
            records.append(FenceRecord(f"test/{k}", "keep_out", frame.geom_to_wgs84(poly)))
    keep_in = None
    if draw(st.booleans()):
        keep_in = wavy(draw(st.sampled_from([8, 300])), 0, 0, 6000, 1, noise=20)
        records.append(FenceRecord("test/in", "keep_in", frame.geom_to_wgs84(keep_in)))
    return lon0, lat0, records


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(full_resolution_sets(), st.sampled_from([64, 64, 2]))
def test_navio2_fences_are_the_fences_and_contain_them(fs, kb):
    lon0, lat0, records = fs
    if not records:
        return
    profile = navio2_profile(kb)
    area = LocalFrame(lon0, lat0).geom_to_wgs84(shapely.box(-3000, -3000, 3000, 3000))
    result = compile_fences(records, area, profile, distance_m=1e5)
    assert len(result.items) <= profile.items and storage_bytes(result.items) <= profile.bytes
    verify = VerifyFrame(lon0, lat0)
    out, keep_in, discs, counts = onboard_shapes(result.items, verify)
    union = shapely.union_all(out) if out else shapely.Polygon()
    for rec in records:
        local = verify.local(rec.geometry)
        n = len(rec.geometry.exterior.coords) - 1
        if rec.kind == "keep_in":  # the onboard inclusion lies inside the keep-in fence
            assert len(keep_in) == 1 and local.covers(keep_in[0])
            continue
        pts = shapely.get_coordinates(local)
        in_disc = any(np.all(np.hypot(*(pts - [x, y]).T) <= r) for x, y, r in discs)
        assert in_disc or union.covers(local), f"{rec.site_id} sticks out of the onboard fence"
    if kb == 64:  # room for everything: each fence is stored as itself, no merge, no circle
        assert result.merges == [] and discs == []
        for rec in records:
            if rec.kind == "keep_in":
                continue
            local = verify.local(rec.geometry)
            n = len(rec.geometry.exterior.coords) - 1
            mine = [(p, v) for p, v in zip(out, counts) if p.covers(local)]
            assert mine, rec.site_id
            stored, vertices = min(mine, key=lambda pv: pv[0].area)
            if n <= 255:  # its own vertices, PAD_M out (a bevel at a spike adds one)
                assert n - 2 <= vertices <= min(255, n + 5)
                assert stored.area - local.area <= 2.5 * PAD_M * local.length + 1.0
            else:  # simplified outward to at most 255, at little cost in area (a noisy
                # 60 m fence of 700 vertices may keep far fewer: its noise is smoothed away)
                assert vertices <= 255
                assert stored.area - local.area <= 0.02 * local.area + 2.5 * PAD_M * local.length


def test_a_fence_whose_edges_bow_goes_onboard_as_its_own_vertices():
    """At 75°N a triangle 700 m across is read with dozens of vertices along its bowed lon/lat
    edges; onboard it is its own three vertices, 5 cm out, and read as ArduPilot reads them
    they contain it (found by the property test above: it took 7-9 vertices)."""
    tri = shapely.Polygon([(-0.049, 75.0), (-0.068, 75.003), (-0.068, 74.997)])
    verify = VerifyFrame(0.0, 75.0)
    area = LocalFrame(0.0, 75.0).geom_to_wgs84(shapely.box(-3000, -3000, 3000, 3000))
    for kind in ("keep_out", "keep_in"):
        result = compile_fences([FenceRecord("t", kind, tri)], area, navio2_profile(64))
        out, keep_in, discs, counts = onboard_shapes(result.items, verify)
        local = verify.local(tri)
        assert len(local.exterior.coords) > 30  # its reading bows
        if kind == "keep_out":
            assert counts == [3] and discs == [] and out[0].covers(local)
        else:
            assert len(result.items) == 3 and local.covers(keep_in[0])


def test_demo_scene_at_full_resolution(tmp_path):
    """Every keep-out fence of the demo scene goes onboard as itself: no circle, no merge."""
    from alphafence.fencing.pipeline import BuildOptions, build_fences
    from alphafence.onboard.compile import compile_fences
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    rules = load_rules()
    scene = __import__("alphafence").__path__[0] + "/data/demo-scene.geojson"
    built = build_fences(read_database([scene], rules).features, rules, BuildOptions())
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in built.fences]
    keep_out = [r for r in records if r.kind == "keep_out"]
    area = shapely.union_all([r.geometry for r in keep_out]).envelope
    copter = compile_fences(records, area, PROFILES["copter"], distance_m=0.0)
    navio2 = compile_fences(records, area, PROFILES["navio2"], distance_m=0.0)
    assert navio2.merges == [] and all(p.chosen.kind == "polygon" for p in navio2.pieces)
    assert len(navio2.pieces) == sum(len(shapely.get_parts(r.geometry)) for r in keep_out)
    for p in navio2.pieces:
        assert p.chosen.items == len(p.local.exterior.coords) - 1 or p.chosen.items <= 255
    assert navio2.loss_m2 < copter.loss_m2 / 20


# ------------------------------------------------------------------ upload and storage


def polygon(n, k=0):
    """A fence polygon of n vertices (the k-th, side by side) as items."""
    lon0, lat0 = 14.49 + 0.01 * k, 35.86
    return [
        FenceItem(
            POLYGON_EXCLUSION,
            float(n),
            round(lon0 + 0.003 * math.cos(2 * math.pi * i / n), 7),
            round(lat0 + 0.003 * math.sin(2 * math.pi * i / n), 7),
        )
        for i in range(n)
    ]


BIG = polygon(200) + polygon(200, 1) + polygon(100, 2)  # 500 items, 4.0 kB: needs BRD_SD_FENCE 4


def plan_file(tmp_path, items):
    path = tmp_path / "onboard.plan"
    path.write_text(qgc_plan.dumps(qgc_plan.plan_document(items)))
    return str(path)


async def upload_cli(fake, tmp_path, *extra):
    argv = ["upload", plan_file(tmp_path, BIG), "--connect", fake.url, "--allow-unsigned"]
    return await asyncio.to_thread(main, [*argv, "--profile", "navio2", *extra])


def sent_anything(fake) -> bool:
    """Whether the fake got anything that changes it: a fence, a parameter, a reboot."""
    return bool(
        fake.received("MISSION_COUNT")
        or fake.received("PARAM_SET")
        or [
            c
            for c in fake.received("COMMAND_LONG")
            if c[0] == mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN
        ]
    )


def errors(capsys) -> str:
    """The one error line the command printed (besides the unsigned-fences warning)."""
    lines = [x for x in capsys.readouterr().err.splitlines() if not x.startswith("warning:")]
    assert len(lines) == 1, lines
    return lines[0]


def test_big_fence_needs_file_storage():
    assert kb_needed(BIG) == 4 and len(BIG) > 70


async def test_storage_too_small_stops_before_sending(tmp_path, capsys, link):
    async with FakeVehicle(params={"BRD_SD_FENCE": 0}) as fake:
        code = await upload_cli(fake, tmp_path)
    err = errors(capsys)
    assert code == 3
    assert err == (
        "alphafence upload: error: BRD_SD_FENCE is 0 kB on the vehicle; this fence needs 4 kB: "
        "set BRD_SD_FENCE to at least 4 and reboot the vehicle, or upload with --reboot"
    )
    assert not sent_anything(fake) and fake.fence == []


async def test_reboot_refused_while_armed(tmp_path, capsys, link):
    async with FakeVehicle(params={"BRD_SD_FENCE": 2}, armed=True) as fake:
        code = await upload_cli(fake, tmp_path, "--reboot")
    err = errors(capsys)
    assert code == 3
    assert "BRD_SD_FENCE is 2 kB" in err and "armed" in err and "disarmed" in err
    assert not sent_anything(fake) and fake.reboots == 0


async def test_reboot_path_sets_reboots_then_uploads(tmp_path, capsys, link):
    async with FakeVehicle(params={"BRD_SD_FENCE": 0}, reboot_seconds=1.5) as fake:
        code = await upload_cli(fake, tmp_path, "--reboot")
        out = capsys.readouterr().out
        assert code == 0, out
        assert fake.reboots == 1 and fake.params["BRD_SD_FENCE"] == 64
        assert (fake.max_items, fake.storage_size) == (8191, 65535)
        held = [FenceItem(it.command, it.param1, it.lon, it.lat) for it in fake.fence]
        assert same_items(BIG, held) == []
        # the order of what the vehicle saw: read, set (and read back), reboot, boot, read
        # again, then the fence
        steps = []
        for _, what, name, detail in fake.log:
            if what in ("reboot", "boot"):
                steps.append(what)
            elif what == "in" and name in ("PARAM_SET", "PARAM_REQUEST_READ", "MISSION_COUNT"):
                steps.append(name)
            elif what == "in" and name == "COMMAND_LONG" and detail[0] == 246:
                steps.append("REBOOT_COMMAND")
        first = {s: steps.index(s) for s in set(steps)}
        assert first["PARAM_REQUEST_READ"] < first["PARAM_SET"] < first["REBOOT_COMMAND"]
        assert first["REBOOT_COMMAND"] < first["reboot"] < first["boot"] < first["MISSION_COUNT"]
        assert "PARAM_REQUEST_READ" in steps[first["boot"] : first["MISSION_COUNT"]]
        assert steps.count("REBOOT_COMMAND") == 1
    assert "rebooted" in out and "uploaded 500 fence items" in out


async def test_enough_storage_uploads_without_reboot(tmp_path, capsys, link):
    async with FakeVehicle(params={"BRD_SD_FENCE": 8}, max_items=1024, storage_size=8192) as fake:
        code = await upload_cli(fake, tmp_path, "--reboot")
        assert code == 0 and fake.reboots == 0 and not fake.received("PARAM_SET")
        assert len(fake.fence) == 500
    assert "BRD_SD_FENCE is 8 kB on the vehicle; this fence needs 4 kB" in capsys.readouterr().out


async def test_parameter_set_but_not_rebooted_says_so(tmp_path, capsys, link):
    # BRD_SD_FENCE reads 64, but the vehicle still has its 560 bytes: it was set since boot
    async with FakeVehicle(params={"BRD_SD_FENCE": 64}) as fake:
        code = await upload_cli(fake, tmp_path)
    err = errors(capsys)
    assert code == 3
    assert "Only 70 items are supported" in err
    assert "BRD_SD_FENCE takes effect at boot" in err


async def test_reboot_waits_for_the_new_boot(link):
    async with FakeVehicle(reboot_seconds=1.0) as fake:
        async with open_vehicle(fake.url, 5.0) as vehicle:
            rep = await reboot_vehicle(vehicle, timeout=20.0)
    assert fake.reboots == 1
    assert rep.boot_ms_before >= 60_000 and rep.boot_ms_after < rep.boot_ms_before
    # not before the fake was back: the boot time it reports came from the fake after its boot
    log = [(what, name, detail) for _, what, name, detail in fake.log]
    booted = log.index(("boot", "", (fake.max_items, fake.storage_size)))
    assert ("out", "SYSTEM_TIME", rep.boot_ms_after) in log[booted:]
    assert rep.back_s > 0


async def test_reboot_that_never_comes_back_times_out_saying_so(link):
    async with FakeVehicle(reboot_seconds=60.0) as fake:
        async with open_vehicle(fake.url, 5.0) as vehicle:
            with pytest.raises(RebootError) as err:
                await reboot_vehicle(vehicle, timeout=4.0)
    assert "did not come back within 4 s" in str(err.value) and "\n" not in str(err.value)


async def test_download_guard_follows_the_storage(link):
    many = [it for k in range(6) for it in polygon(200, k)]  # 1200 items: over the old 1000
    async with FakeVehicle(fence=many, max_items=8191, storage_size=65535) as fake:
        async with open_vehicle(fake.url, 5.0) as vehicle:
            assert same_items(many, await download_fence(vehicle)) == []
            with pytest.raises(FenceTransferError) as err:
                await download_fence(vehicle, max_items=PROFILES["copter"].items)
            assert "the vehicle sent 1200 fence items (over 70" in str(err.value)
            smaller = many[:800]
            rep = await upload_fence(vehicle, smaller, capacity=PROFILES["navio2"].items)
            assert rep.verified and rep.items == 800


def test_cli_refuses_sizes_and_flags_that_do_not_apply(tmp_path, capsys):
    plan = plan_file(tmp_path, polygon(5))
    base = ["upload", plan, "--allow-unsigned", "--dry-run"]
    assert main([*base, "--profile", "navio2", "--sd-fence-kb", "65"]) == 2
    assert main([*base, "--sd-fence-kb", "8"]) == 2
    assert main([*base, "--reboot"]) == 2
    err = capsys.readouterr().err
    assert "--sd-fence-kb" in err and "navio2" in err and "--reboot" in err
    assert main([*base, "--profile", "navio2", "--sd-fence-kb", "8", "--reboot"]) == 0


def test_sitl_verb_takes_parameters(capsys):
    from alphafence.cli.sitl import param_value

    assert param_value("BRD_SD_FENCE=64") == ("BRD_SD_FENCE", 64)
    assert param_value("FENCE_MARGIN=2.5") == ("FENCE_MARGIN", 2.5)
    for bad in ("BRD_SD_FENCE", "brd_sd_fence=1", "BRD_SD_FENCE=x", "X=nan"):
        assert main(["sitl", "--home", "egham", "--param", bad]) == 2
    assert capsys.readouterr().err.count("--param") == 4
