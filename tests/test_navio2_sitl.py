"""Issue 11 test (a) on real ArduPilot SITL: ``upload --profile navio2 --reboot`` of every Malta
keep-out fence in the 5 km box at full resolution. SITL starts without BRD_SD_FENCE (its 560
bytes of fence storage); the upload sets BRD_SD_FENCE, reboots SITL (which re-executes itself),
waits for the new boot, uploads and verifies item by item; an independent download then
matches the compiled items, and the fence lives in ``fence.stg`` in the instance's own
temporary directory."""

from __future__ import annotations

import asyncio
import re

import pytest
import shapely

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.mavlink.storage import PROFILES, file_storage_bytes, storage_bytes
from alphafence.onboard.compile import compile_fences
from alphafence.vehicle.fence_transfer import download_fence, same_items
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import read_params
from alphafence.vehicle.sd_fence import kb_needed

pytestmark = pytest.mark.sitl

BOX = "14.4583,35.8685,14.5137,35.9135"  # the 5 km box around the airport


@pytest.mark.parametrize("sitl", [{"home": "malta_airport", "speedup": 5}], indirect=True)
async def test_navio2_reboot_then_all_malta_fences_at_full_resolution(
    sitl, malta, tmp_path, capsys
):
    fences = tmp_path / "fences.geojson"
    assert await asyncio.to_thread(main, ["build", str(malta), "-o", str(fences)]) == 0
    compile_args = ["--profile", "navio2", "--bbox", BOX, "--distance", "0"]
    # what the upload compiles, compiled here too
    plan = tmp_path / "onboard.plan"
    assert (
        await asyncio.to_thread(main, ["compile", str(fences), *compile_args, "-o", str(plan)]) == 0
    )
    items = read_plan_fence(str(plan))
    # every keep-out fence in the box as itself: no merge, no circle, its own vertices
    records = read_fences(str(fences))
    box = shapely.box(*(float(v) for v in BOX.split(",")))
    compiled = compile_fences(records, box, PROFILES["navio2"], distance_m=0.0)
    assert same_items(items, compiled.items) == []
    assert compiled.merges == [] and all(p.chosen.kind == "polygon" for p in compiled.pieces)
    keep_out = {r.site_id: r.geometry for r in records if r.kind == "keep_out"}
    assert {p.sources[0] for p in compiled.pieces} == {
        sid for sid, g in keep_out.items() if g.intersects(box)
    }
    for p in compiled.pieces:  # each fence inside the box with its own vertices (5 cm out)
        fence = keep_out[p.sources[0]]
        if box.contains(fence):
            assert p.chosen.items == len(fence.exterior.coords) - 1, p.sources
    assert len(compiled.pieces) > 50 and len(items) > 1000, (len(compiled.pieces), len(items))
    need = kb_needed(items)
    assert 8 <= need <= 64 and storage_bytes(items) <= file_storage_bytes(need)

    async with open_vehicle(sitl.connection_url) as vehicle:
        before = await read_params(vehicle, ["BRD_SD_FENCE"])
    assert before["BRD_SD_FENCE"] == 0
    capsys.readouterr()

    upload = ["upload", str(fences), "--allow-unsigned", "--connect", sitl.connection_url]
    code = await asyncio.to_thread(main, [*upload, *compile_args, "--reboot"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "BRD_SD_FENCE set to 64 kB (was 0)" in out
    back = re.search(r"back (\d+\.\d) s after the command", out)
    assert back and float(back.group(1)) < 30, out
    assert f"uploaded {len(items)} fence items and read them back identical" in out

    # SITL kept its process (it re-executed itself) and its working directory
    assert sitl.running
    stg = sitl.workdir / "fence.stg"
    assert stg.is_file() and stg.stat().st_size == file_storage_bytes(64)

    async with open_vehicle(sitl.connection_url) as vehicle:
        after = await read_params(vehicle, ["BRD_SD_FENCE"])
        got = await download_fence(vehicle, PROFILES["navio2"].items)
    assert after["BRD_SD_FENCE"] == 64
    assert same_items(items, got) == []


@pytest.mark.parametrize(
    "sitl",
    [{"home": "malta_airport", "speedup": 5, "param_values": {"BRD_SD_FENCE": 32}}],
    indirect=True,
)
async def test_sitl_started_with_file_storage_takes_a_big_fence_without_reboot(sitl):
    from alphafence.vehicle.fence_transfer import upload_fence
    from alphafence.vehicle.sd_fence import ensure_fence_storage

    from .test_navio2 import polygon

    assert (sitl.workdir / "fence.stg").stat().st_size == file_storage_bytes(32)
    items = [it for k in range(8) for it in polygon(255, k)]  # 2040 items, 16,341 bytes
    async with open_vehicle(sitl.connection_url) as vehicle:
        got = await ensure_fence_storage(vehicle, items, 32, reboot=True)
        assert (got.have_kb, got.need_kb, got.set_kb, got.reboot) == (32, 16, None, None)
        rep = await upload_fence(vehicle, items, capacity=PROFILES["sd-fence"].items)
        assert rep.verified and rep.items == 2040
