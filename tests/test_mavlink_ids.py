"""Every MAVLink number in alphafence.mavlink.ids is MAVLink's own, as pymavlink generates it."""

from __future__ import annotations

import pytest

from alphafence.mavlink import ids

mavlink = pytest.importorskip("pymavlink.dialects.v20.ardupilotmega")

NAMES = [n for n in dir(ids) if n.isupper() and isinstance(getattr(ids, n), int)]


def test_the_table_is_not_empty():
    assert len(NAMES) >= 25


@pytest.mark.parametrize("name", NAMES)
def test_each_number_is_mavlinks(name):
    assert hasattr(mavlink, name), f"{name} is not a MAVLink name (pymavlink's dialect has none)"
    assert getattr(ids, name) == getattr(mavlink, name)


def test_groups_hold_only_named_commands():
    named = {getattr(ids, n) for n in NAMES if n.startswith("MAV_CMD_")}
    assert ids.FENCE_COMMANDS <= named
    assert ids.NAV_POSITION_COMMANDS <= named
    assert set(ids.NAV_COMMAND_NAMES) <= named
    assert all(
        getattr(mavlink, "MAV_CMD_NAV_FENCE_" + s) in ids.FENCE_COMMANDS
        for s in (
            "RETURN_POINT",
            "POLYGON_VERTEX_INCLUSION",
            "POLYGON_VERTEX_EXCLUSION",
            "CIRCLE_INCLUSION",
            "CIRCLE_EXCLUSION",
        )
    )


def _nav_commands():
    return {
        v: entry
        for v, entry in mavlink.enums["MAV_CMD"].items()
        if entry.name.startswith("MAV_CMD_NAV_")
    }


@pytest.mark.may_skip("pymavlink 2.4.20, the oldest supported, has no has_location in its enums")
def test_every_nav_command_with_a_position_is_flown():
    # a mission check that skips a NAV command it does not list misses its leg (issue 14:
    # NAV_PAYLOAD_PLACE); pymavlink's own table says which commands have a position
    navs = _nav_commands()
    assert {16, 17, 18, 19, 21, 22, 94} <= set(navs)
    if not hasattr(navs[16], "has_location"):
        pytest.skip("this pymavlink's enums do not say which commands have a location")
    for v, entry in navs.items():
        label = entry.param.get(5, "").lower()
        flown_position = (
            entry.has_location and label.startswith("latitude") and v < ids.MAV_CMD_NAV_LAST
        )
        assert ids.flies_to_position(v) == flown_position, (v, entry.name, entry.param.get(5))


def test_nav_groups_split_the_nav_range():
    assert not ids.NAV_POSITION_COMMANDS & ids.NAV_NOT_FLOWN
    assert ids.MAV_CMD_NAV_PAYLOAD_PLACE in ids.NAV_POSITION_COMMANDS
    assert not any(ids.flies_to_position(c) for c in ids.FENCE_COMMANDS)
    assert not ids.flies_to_position(ids.MAV_CMD_NAV_RALLY_POINT)
    assert not ids.flies_to_position(ids.MAV_CMD_DO_JUMP)
