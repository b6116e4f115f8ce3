"""Fence upload, read-back and parameters against real ArduPilot SITL, on each vehicle link
(the ``link`` fixture: pymavlink and MAVSDK; the CLI follows ``$ALPHAFENCE_LINK``)."""

import math

import numpy as np
import pytest
import shapely

from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.fencing.pipeline import BuildOptions, build_fences
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_EXCLUSION, FenceItem
from alphafence.mavlink.storage import PROFILES, storage_bytes
from alphafence.onboard.compile import compile_fences
from alphafence.vehicle.fence_transfer import (
    FenceTransferError,
    download_fence,
    same_items,
    upload_fence,
)
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import PROFILES as PARAMS
from alphafence.vehicle.params import apply_params

pytestmark = [pytest.mark.sitl, pytest.mark.usefixtures("link")]
MALTA_AIRPORT = {"home": "malta_airport", "speedup": 5}


def polygon_items(n, lon0=14.49, lat0=35.86, radius=300.0):
    frame = LocalFrame(lon0, lat0)
    ang = np.linspace(0, 2 * math.pi, n, endpoint=False)
    lon, lat = frame.to_wgs84(radius * np.cos(ang), radius * np.sin(ang))
    return [
        FenceItem(POLYGON_EXCLUSION, float(n), round(a, 7), round(b, 7)) for a, b in zip(lon, lat)
    ]


@pytest.mark.parametrize("sitl", [MALTA_AIRPORT], indirect=True)
async def test_compiled_malta_fence_round_trip(sitl, malta_db, rules):
    result = build_fences(malta_db.features, rules, BuildOptions())
    records = [FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m) for f in result.fences]
    area = shapely.box(14.46, 35.84, 14.50, 35.87)
    compiled = compile_fences(records, area, PROFILES["copter"], distance_m=1000)
    assert 20 <= len(compiled.items) <= 70 and storage_bytes(compiled.items) <= 560
    async with open_vehicle(sitl.connection_url) as vehicle:
        report = await upload_fence(vehicle, compiled.items)
        assert report.verified and report.items == len(compiled.items)
        again = await download_fence(vehicle)  # an independent second read
        assert same_items(compiled.items, again) == []


@pytest.mark.parametrize("sitl", [MALTA_AIRPORT], indirect=True)
async def test_the_malta_box_uploads_with_the_vehicles_home_clear(sitl, malta, tmp_path, capsys):
    """The box of the first report, on ArduPilot with the copter profile: compiled round the
    home the vehicle reports (Luqa), every keep-out fence held, home in none."""
    import asyncio

    from alphafence.cli import main
    from alphafence.fencefiles.fence_read import read_fence_file

    from .test_home_clear import BOX, HOME, assert_clear_and_holding, far_from

    fences = tmp_path / "fences.geojson"
    assert main(["build", str(malta), "-o", str(fences), "-q"]) == 0
    argv = ["upload", str(fences), "--bbox", ",".join(map(str, BOX)), "--profile", "copter",
            "--connect", sitl.connection_url, "--allow-unsigned"]  # fmt: skip
    assert await asyncio.to_thread(main, argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "home 35.86" in out and "the fence leaves them 25 m clear" in out
    async with open_vehicle(sitl.connection_url) as vehicle:
        held = await download_fence(vehicle)
    records = read_fence_file(fences)
    assert_clear_and_holding(records, held, far_from(records, shapely.box(*BOX)), "ardupilot",
                             HOME)  # fmt: skip


@pytest.mark.parametrize("sitl", [MALTA_AIRPORT], indirect=True)
async def test_capacity_edge_and_old_fence_kept(sitl):
    full = polygon_items(69)  # 4 + 2 + 8*69 + 1 = 559 of 560 bytes
    assert storage_bytes(full) == 559
    async with open_vehicle(sitl.connection_url) as vehicle:
        await upload_fence(vehicle, full)
        too_big = polygon_items(70)  # 567 bytes: over the storage
        with pytest.raises(FenceTransferError) as err:
            await upload_fence(vehicle, too_big)
        msg = str(err.value)
        assert "failed" in msg and "still holds its previous fence (69 items)" in msg
        assert "Fence exceeds storage size" in msg  # the vehicle's own words
        assert same_items(full, await download_fence(vehicle)) == []
        with pytest.raises(FenceTransferError) as err:
            await upload_fence(vehicle, polygon_items(80))  # more items than it holds at all
        assert "69 items" in str(err.value) and "no room" in str(err.value)
        assert "Only 70 items are supported" in str(err.value)


@pytest.mark.parametrize("sitl", [MALTA_AIRPORT], indirect=True)
async def test_fence_parameters_applied(sitl):
    async with open_vehicle(sitl.connection_url) as vehicle:
        got = await apply_params(vehicle, PARAMS["copter-brake"])
        assert got.values["FENCE_ACTION"] == 4 and got.values["FENCE_ENABLE"] == 1
        assert got.values["FENCE_ALT_MAX"] == pytest.approx(120.0)


@pytest.mark.parametrize("sitl", [{"home": "egham", "speedup": 5}], indirect=True)
async def test_cli_upload_then_download(sitl, tmp_path):
    import asyncio

    from alphafence.cli import main
    from alphafence.cli.demo import scene_path
    from alphafence.fencefiles.qgc_plan import read_plan_fence

    fences = tmp_path / "f.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    code = await asyncio.to_thread(
        main,
        [
            "upload",
            str(fences),
            "--connect",
            sitl.connection_url,
            "--bbox=-0.58,51.42,-0.52,51.44",
            "--params",
            "copter-rtl",
            "--allow-unsigned",
        ],
    )
    assert code == 0
    out = tmp_path / "onboard.plan"
    assert (
        await asyncio.to_thread(
            main, ["download", "--connect", sitl.connection_url, "-o", str(out)]
        )
        == 0
    )
    items = read_plan_fence(out)
    assert len(items) > 5 and all(i.command in (5002, 5004) for i in items)
