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
