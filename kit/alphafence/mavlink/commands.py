"""COMMAND_LONG built in one place, for every path that sends one.

MAVSDK's ``mavlink_direct`` plugin takes a message as its name plus JSON fields; pymavlink
takes the fields as arguments. Both build them here.
"""

from __future__ import annotations

import json

from alphafence.mavlink import ids


def command_long_fields(target_system, target_component, command, *params) -> dict:
    """The fields of a COMMAND_LONG: up to seven params, the rest zero, confirmation 0.

    Parameters
    ----------
    target_system, target_component : int
        Whom the command is for.
    command : int
        A ``MAV_CMD`` from :mod:`alphafence.mavlink.ids`.
    *params : float
        param1, param2, ... (at most seven).

    Examples
    --------
    >>> f = command_long_fields(1, 1, ids.MAV_CMD_SET_MESSAGE_INTERVAL, 87, 1e5)
    >>> f["command"], f["param1"], f["param2"], f["param7"]
    (511, 87.0, 100000.0, 0.0)
    """
    if len(params) > 7:
        raise ValueError(f"COMMAND_LONG has 7 params, not {len(params)}")
    p = [float(v) for v in params] + [0.0] * (7 - len(params))
    fields = {
        "target_system": int(target_system),
        "target_component": int(target_component),
        "command": int(command),
        "confirmation": 0,
    }
    fields.update({f"param{i + 1}": v for i, v in enumerate(p)})
    return fields


def command_long_json(target_system, target_component, command, *params) -> str:
    """:func:`command_long_fields` as the JSON text MAVSDK's ``mavlink_direct`` sends."""
    return json.dumps(command_long_fields(target_system, target_component, command, *params))


def set_message_interval(target_system, message_id, interval_us, target_component=1) -> dict:
    """COMMAND_LONG fields asking for ``message_id`` every ``interval_us`` microseconds
    (0: the vehicle's default rate, -1: stop)."""
    return command_long_fields(
        target_system, target_component, ids.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, interval_us
    )
