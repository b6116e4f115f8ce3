"""What an upload verifies after the vehicle has acknowledged it, against the scripted ArduPilot
peer (tests/fake_vehicle.py) on each vehicle link: a fence the vehicle stores other than it was
sent (a vertex a few 1e-7 degrees off, an item left out) and a fence parameter that does not
take the value set are failures, and the failure says what the vehicle holds.

The vehicle acknowledges each of these uploads (MISSION_ACK ACCEPTED, or PARAM_VALUE): only
the read-back can tell. Without it (upload_fence's comparison, apply_params' read-back) every
upload test here fails.
"""

from __future__ import annotations

import asyncio
import doctest

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from alphafence.cli import main
from alphafence.fencefiles.qgc_wpl import waypoints_text
from alphafence.geo.coords import to_e7
from alphafence.mavlink.items import FenceItem
from alphafence.vehicle import fence_transfer
from alphafence.vehicle.fence_transfer import FenceTransferError, same_items, upload_fence
from alphafence.vehicle.link import open_vehicle
from alphafence.vehicle.params import PROFILES, ParamError, apply_params, read_params
from tests.fake_vehicle import FakeVehicle, Faults
from tests.test_upload_faults import NEW, PREVIOUS, held

# the fence parameters as a vehicle has them before a profile is applied (the fake answers
# integers as INT16, as ArduPilot declares FENCE_ENABLE, FENCE_TYPE and FENCE_ACTION)
BEFORE = {
    "FENCE_ENABLE": 0,
    "FENCE_TYPE": 7,
    "FENCE_ACTION": 1,
    "FENCE_MARGIN": 3.0,
    "FENCE_ALT_MAX": 100.0,
}
BRAKE = PROFILES["copter-brake"]  # FENCE_ACTION 4


def off_by(seq, **e7):
    """Faults storing item ``seq`` of NEW that many 1e-7 degrees off (x = lat, y = lon)."""
    it = NEW[seq]
    stored = {"x": to_e7(it.lat) + e7.get("x", 0), "y": to_e7(it.lon) + e7.get("y", 0)}
    return Faults(store_fields={seq: stored})


async def upload_error(fake, items=NEW) -> FenceTransferError:
    async with open_vehicle(fake.url, timeout=5.0) as vehicle:
        with pytest.raises(FenceTransferError) as err:
            await asyncio.wait_for(upload_fence(vehicle, items), 30.0)
    return err.value


def differences(err, holds) -> str:
    """The differences an upload's error names, after checking that it is one line ending with
    what the vehicle holds (the vehicle's STATUSTEXTs may come between: "Fence Indexed OK")."""
    msg = str(err)
    assert "\n" not in msg and err.holds == holds, msg
    head, *says, tail = msg.split(" | ")
    assert tail == holds and all(s.startswith("vehicle: ") for s in says), msg
    prefix = "the fence read back differs from the one sent: "
    assert head.startswith(prefix), msg
    return head[len(prefix) :]


def assert_acknowledged_and_stored(fake):
    """The vehicle took the upload: the failure can only come from the read-back."""
    assert fake.upload_results == [mav.MAV_MISSION_ACCEPTED] and fake.fence_writes == 1


# ------------------------------------------------------------------ the fence


@pytest.mark.parametrize(
    "faults, seq",
    [(off_by(3, x=3), 3), (off_by(5, y=-2), 5), (off_by(9, x=1, y=1), 9)],
    ids=["vertex-lat-3e-7", "vertex-lon-2e-7", "return-point-1e-7"],
)
@pytest.mark.usefixtures("link")
async def test_an_item_stored_off_by_a_few_1e7_degrees(faults, seq):
    async with FakeVehicle(fence=PREVIOUS, faults=faults) as fake:
        err = await upload_error(fake)
    assert_acknowledged_and_stored(fake)
    stored = held(fake)
    assert stored[seq] != NEW[seq] and len(stored) == len(NEW)  # the fault is what it says
    # exactly the one item, as sent and as the vehicle holds it
    holds = f"the vehicle holds {len(NEW)} fence items"
    assert differences(err, holds) == f"item {seq}: sent {NEW[seq]}, read {stored[seq]}"


@pytest.mark.parametrize("seq", [8, 9], ids=["circle", "return-point"])
@pytest.mark.usefixtures("link")
async def test_an_item_left_out(seq):
    # the circle (item 8) or the return point (item 9, the last) is acknowledged and not
    # stored: the rest is still a valid fence, so only the comparison with what was sent
    # tells; it names the item the vehicle does not hold, and nothing else
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(store_drop={seq})) as fake:
        err = await upload_error(fake)
    assert_acknowledged_and_stored(fake)
    assert same_items(NEW[:seq] + NEW[seq + 1 :], held(fake)) == []  # the fault is as it says
    holds = f"the vehicle holds {len(NEW) - 1} fence items"
    assert differences(err, holds) == (
        f"{len(NEW)} items sent, {len(NEW) - 1} read back; item {seq} not read back: {NEW[seq]}"
    )


@pytest.mark.usefixtures("link")
async def test_a_polygon_vertex_left_out_is_an_invalid_fence():
    # without vertex 3 the polygon's items say 8 vertices and there are 7: the read-back is
    # refused as a fence, naming where it breaks
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(store_drop={3})) as fake:
        err = await upload_error(fake)
    assert_acknowledged_and_stored(fake)
    assert len(fake.fence) == len(NEW) - 1
    assert str(err).startswith(
        "the vehicle sent an invalid fence: item 7: a polygon of 8 vertices starting at item 0"
    ), str(err)


def test_same_items_examples_run():
    result = doctest.testmod(fence_transfer, optionflags=doctest.ELLIPSIS)
    assert result.attempted and not result.failed


def test_same_items_names_each_difference():
    # by the item numbers sent and read: one left out, one changed after it, one added
    changed = FenceItem(NEW[6].command, NEW[6].param1, NEW[6].lon + 2e-7, NEW[6].lat)
    extra = FenceItem(NEW[9].command, 0.0, 14.5, 35.9)
    got = NEW[:2] + NEW[3:6] + [changed] + NEW[7:] + [extra]
    assert same_items(NEW, got) == [
        f"item 2 not read back: {NEW[2]}",
        f"item 6: sent {NEW[6]}, read as item 5: {changed}",
        f"read item 9 was not sent: {extra}",
    ]
    assert same_items(NEW, got[:-1])[0] == f"{len(NEW)} items sent, {len(NEW) - 1} read back"
    assert same_items(NEW, list(NEW)) == [] and same_items([], []) == []
    # a radius is compared to 0.1 %, a vertex count exactly
    circle = NEW[8]
    assert same_items([circle], [FenceItem(circle.command, 75.55, circle.lon, circle.lat)]) == []
    assert len(same_items([circle], [FenceItem(circle.command, 75.6, circle.lon, circle.lat)]))
    vertex = NEW[0]
    assert len(same_items([vertex], [FenceItem(vertex.command, 9.0, vertex.lon, vertex.lat)]))


async def test_a_read_back_names_its_first_differences_and_counts_the_rest():
    # every vertex of the polygon stored 1e-7 degrees north: the first four, then how many more
    moved = {seq: {"x": to_e7(NEW[seq].lat) + 1} for seq in range(8)}
    async with FakeVehicle(fence=PREVIOUS, faults=Faults(store_fields=moved)) as fake:
        err = await upload_error(fake)
    stored = held(fake)
    first = [f"item {k}: sent {NEW[k]}, read {stored[k]}" for k in range(4)]
    holds = f"the vehicle holds {len(NEW)} fence items"
    assert differences(err, holds) == "; ".join([*first, "and 4 more differences"])


async def upload_cli(fake, tmp_path, *extra) -> int:
    """``alphafence upload`` of NEW (a .waypoints file: the items in their order) to the fake."""
    path = tmp_path / "onboard.waypoints"
    path.write_text(waypoints_text(NEW))
    argv = ["upload", str(path), "--connect", fake.url, "--allow-unsigned", *extra]
    return await asyncio.to_thread(main, argv)


def error_lines(captured) -> list:
    """The error lines the command printed, besides the unsigned-fences warning."""
    return [x for x in captured.err.splitlines() if not x.startswith("warning:")]


@pytest.mark.usefixtures("link")
async def test_cli_upload_says_what_the_vehicle_holds(tmp_path, capsys):
    async with FakeVehicle(fence=PREVIOUS, faults=off_by(3, x=3)) as fake:
        code = await upload_cli(fake, tmp_path)
    captured = capsys.readouterr()
    assert code == 3 and "uploaded" not in captured.out
    [line] = error_lines(captured)
    assert line.startswith(
        "alphafence upload: error: the fence read back differs from the one sent: "
        f"item 3: sent {NEW[3]}, read {held(fake)[3]} | "
    ), line
    assert line.endswith(f" | the vehicle holds {len(NEW)} fence items"), line


# ------------------------------------------------------------------ parameters


@pytest.mark.parametrize("echo", [False, True], ids=["answers-kept-value", "answers-value-set"])
@pytest.mark.usefixtures("link")
async def test_a_parameter_that_keeps_its_value(echo):
    # FENCE_ACTION stays 1 whatever is set: the vehicle answers the PARAM_SET with the value it
    # kept, or (echo) with the value asked for while it keeps its own; reading it back tells
    faults = Faults(param_keeps={"FENCE_ACTION": 1}, param_echo_set=echo)
    async with FakeVehicle(params=BEFORE, faults=faults) as fake:
        async with open_vehicle(fake.url, timeout=5.0) as vehicle:
            with pytest.raises(ParamError) as err:
                await asyncio.wait_for(apply_params(vehicle, BRAKE), 60.0)
            after = await read_params(vehicle, BRAKE)
    assert fake.params["FENCE_ACTION"] == after["FENCE_ACTION"] == 1  # what it holds
    assert ("FENCE_ACTION", 4.0) in fake.received("PARAM_SET")  # it was asked for 4
    if echo:
        assert ("FENCE_ACTION", 4) in fake.sent("PARAM_VALUE")  # and said it took 4
    assert str(err.value) == "read back differs: FENCE_ACTION set 4 reads 1"
    # every other parameter was set
    assert {k: v for k, v in after.items() if k != "FENCE_ACTION"} == {
        k: v for k, v in BRAKE.items() if k != "FENCE_ACTION"
    }


@pytest.mark.usefixtures("link")
async def test_cli_upload_reports_the_parameter_it_could_not_set(tmp_path, capsys):
    faults = Faults(param_keeps={"FENCE_ACTION": 1})
    async with FakeVehicle(fence=PREVIOUS, params=BEFORE, faults=faults) as fake:
        code = await upload_cli(fake, tmp_path, "--params", "copter-brake")
    captured = capsys.readouterr()
    assert code == 3
    assert same_items(NEW, held(fake)) == []  # the fence went, and was verified
    assert "read them back identical" in captured.out
    assert error_lines(captured) == [
        "alphafence upload: error: read back differs: FENCE_ACTION set 4 reads 1"
    ]
