"""Every MAVLink number the kit uses, named once.

The values are MAVLink's ``common`` and ``ardupilotmega`` dialect definitions; a test
(``tests/test_mavlink_ids.py``) checks each one against pymavlink's generated dialect, so a
typo here cannot reach a vehicle. Import the names from here; never type the numbers again.

Examples
--------
>>> from alphafence.mavlink import ids
>>> ids.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
5002
"""

from __future__ import annotations

# -- MAV_CMD: mission items (NAV) -------------------------------------------------------
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_UNLIM = 17
MAV_CMD_NAV_LOITER_TURNS = 18
MAV_CMD_NAV_LOITER_TIME = 19
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_NAV_LAND_LOCAL = 23
MAV_CMD_NAV_TAKEOFF_LOCAL = 24
MAV_CMD_NAV_FOLLOW = 25
MAV_CMD_NAV_CONTINUE_AND_CHANGE_ALT = 30
MAV_CMD_NAV_LOITER_TO_ALT = 31
MAV_CMD_NAV_ROI = 80
MAV_CMD_NAV_PATHPLANNING = 81
MAV_CMD_NAV_SPLINE_WAYPOINT = 82
MAV_CMD_NAV_ALTITUDE_WAIT = 83
MAV_CMD_NAV_VTOL_TAKEOFF = 84
MAV_CMD_NAV_VTOL_LAND = 85
MAV_CMD_NAV_GUIDED_ENABLE = 92
MAV_CMD_NAV_DELAY = 93
MAV_CMD_NAV_PAYLOAD_PLACE = 94
MAV_CMD_NAV_LAST = 95  # NAV commands are numbered below this
MAV_CMD_NAV_RALLY_POINT = 5100

# -- MAV_CMD: mission flow ----------------------------------------------------------------
MAV_CMD_DO_JUMP = 177
MAV_CMD_JUMP_TAG = 600
MAV_CMD_DO_JUMP_TAG = 601

# -- MAV_CMD: fence items (mission type FENCE) ------------------------------------------
MAV_CMD_NAV_FENCE_RETURN_POINT = 5000
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION = 5001
MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION = 5002
MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION = 5003
MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION = 5004

# -- MAV_CMD: commands (COMMAND_LONG) ---------------------------------------------------
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_DO_REPOSITION = 192
MAV_DO_REPOSITION_FLAGS_CHANGE_MODE = 1
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_SET_MISSION_CURRENT = 224
MAV_CMD_MISSION_START = 300
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN = 246
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520

# -- MAV_MODE_FLAG ----------------------------------------------------------------------
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128

# -- MAV_RESULT (COMMAND_ACK) ------------------------------------------------------------
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4
MAV_RESULT_IN_PROGRESS = 5

# -- COPTER_MODE / PLANE_MODE / ROVER_MODE (ArduPilot's custom_mode numbers) ------------
COPTER_MODE_STABILIZE = 0
COPTER_MODE_ACRO = 1
COPTER_MODE_ALT_HOLD = 2
COPTER_MODE_AUTO = 3
COPTER_MODE_GUIDED = 4
COPTER_MODE_LOITER = 5
COPTER_MODE_RTL = 6
COPTER_MODE_LAND = 9
COPTER_MODE_POSHOLD = 16
COPTER_MODE_BRAKE = 17
COPTER_MODE_SMART_RTL = 21
PLANE_MODE_MANUAL = 0
PLANE_MODE_AUTO = 10
PLANE_MODE_RTL = 11
PLANE_MODE_LOITER = 12
PLANE_MODE_GUIDED = 15
PLANE_MODE_QLAND = 20
ROVER_MODE_MANUAL = 0
ROVER_MODE_HOLD = 4
ROVER_MODE_AUTO = 10
ROVER_MODE_RTL = 11
ROVER_MODE_SMART_RTL = 12
ROVER_MODE_GUIDED = 15

# -- EKF_STATUS_FLAGS -------------------------------------------------------------------
EKF_POS_HORIZ_ABS = 16
EKF_CONST_POS_MODE = 128
EKF_PRED_POS_HORIZ_ABS = 512

# -- GPS_FIX_TYPE -----------------------------------------------------------------------
GPS_FIX_TYPE_3D_FIX = 3

# -- MAV_FRAME --------------------------------------------------------------------------
MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
MAV_FRAME_GLOBAL_INT = 5
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MAV_FRAME_GLOBAL_TERRAIN_ALT = 10
MAV_FRAME_GLOBAL_TERRAIN_ALT_INT = 11

# -- POSITION_TARGET_TYPEMASK -----------------------------------------------------------
POSITION_TARGET_TYPEMASK_X_IGNORE = 1
POSITION_TARGET_TYPEMASK_Y_IGNORE = 2
POSITION_TARGET_TYPEMASK_VX_IGNORE = 8
POSITION_TARGET_TYPEMASK_VY_IGNORE = 16
POSITION_TARGET_TYPEMASK_VZ_IGNORE = 32
POSITION_TARGET_TYPEMASK_AX_IGNORE = 64
POSITION_TARGET_TYPEMASK_AY_IGNORE = 128
POSITION_TARGET_TYPEMASK_AZ_IGNORE = 256
POSITION_TARGET_TYPEMASK_YAW_IGNORE = 1024
POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE = 2048

# -- MAV_MISSION_RESULT (MISSION_ACK) ---------------------------------------------------
MAV_MISSION_ACCEPTED = 0
MAV_MISSION_ERROR = 1
MAV_MISSION_UNSUPPORTED_FRAME = 2
MAV_MISSION_UNSUPPORTED = 3
MAV_MISSION_NO_SPACE = 4
MAV_MISSION_INVALID = 5
MAV_MISSION_INVALID_PARAM1 = 6
MAV_MISSION_INVALID_PARAM7 = 12
MAV_MISSION_INVALID_SEQUENCE = 13
MAV_MISSION_DENIED = 14
MAV_MISSION_OPERATION_CANCELLED = 15

# -- MAV_SEVERITY (STATUSTEXT) ----------------------------------------------------------
MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_WARNING = 4

# -- MAV_PARAM_TYPE ---------------------------------------------------------------------
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9

# -- MAV_MISSION_TYPE -------------------------------------------------------------------
MAV_MISSION_TYPE_MISSION = 0
MAV_MISSION_TYPE_FENCE = 1

# -- MAV_AUTOPILOT / MAV_TYPE (as QGroundControl plans name the firmware and vehicle) ----
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8  # not a flight controller (a ground station, a companion)
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_FIXED_WING = 1
MAV_TYPE_QUADROTOR = 2
MAV_TYPE_GCS = 6
MAV_STATE_ACTIVE = 4
MAV_TYPE_GROUND_ROVER = 10
MAV_TYPE_SURFACE_BOAT = 11

# -- message ids ------------------------------------------------------------------------
MAVLINK_MSG_ID_HEARTBEAT = 0
MAVLINK_MSG_ID_SYSTEM_TIME = 2
MAVLINK_MSG_ID_GPS_RAW_INT = 24
MAVLINK_MSG_ID_GLOBAL_POSITION_INT = 33
MAVLINK_MSG_ID_MISSION_CURRENT = 42
MAVLINK_MSG_ID_COMMAND_LONG = 76
MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT = 87
MAVLINK_MSG_ID_FENCE_STATUS = 162
MAVLINK_MSG_ID_EKF_STATUS_REPORT = 193
MAVLINK_MSG_ID_HOME_POSITION = 242
MAVLINK_MSG_ID_AUTOPILOT_VERSION = 148
MAVLINK_MSG_ID_ADSB_VEHICLE = 246
MAVLINK_MSG_ID_STATUSTEXT = 253

# -- groups -----------------------------------------------------------------------------
FENCE_COMMANDS = frozenset(
    {
        MAV_CMD_NAV_FENCE_RETURN_POINT,
        MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
        MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
        MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
        MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
    }
)
"""Every fence item command (5000-5004)."""

NAV_POSITION_COMMANDS = frozenset(
    {
        MAV_CMD_NAV_WAYPOINT,
        MAV_CMD_NAV_LOITER_UNLIM,
        MAV_CMD_NAV_LOITER_TURNS,
        MAV_CMD_NAV_LOITER_TIME,
        MAV_CMD_NAV_LAND,
        MAV_CMD_NAV_TAKEOFF,
        MAV_CMD_NAV_FOLLOW,
        MAV_CMD_NAV_LOITER_TO_ALT,
        MAV_CMD_NAV_PATHPLANNING,
        MAV_CMD_NAV_SPLINE_WAYPOINT,
        MAV_CMD_NAV_VTOL_TAKEOFF,
        MAV_CMD_NAV_VTOL_LAND,
        MAV_CMD_NAV_PAYLOAD_PLACE,
    }
)
"""NAV commands whose params 5-7 are a position the vehicle flies to."""

NAV_NOT_FLOWN = frozenset(
    {
        MAV_CMD_NAV_RETURN_TO_LAUNCH,  # flies home: no position of its own
        MAV_CMD_NAV_LAND_LOCAL,  # params 5-7 are metres in a local frame
        MAV_CMD_NAV_TAKEOFF_LOCAL,
        MAV_CMD_NAV_CONTINUE_AND_CHANGE_ALT,  # an altitude only
        MAV_CMD_NAV_ROI,  # where the camera looks, not where the vehicle flies
        MAV_CMD_NAV_ALTITUDE_WAIT,
        MAV_CMD_NAV_GUIDED_ENABLE,
        MAV_CMD_NAV_DELAY,
        MAV_CMD_NAV_LAST,
    }
)
"""NAV commands (below MAV_CMD_NAV_LAST) that move the vehicle to no position of their own."""


def flies_to_position(command) -> bool:
    """Whether a mission item of this command flies the vehicle to its params 5-7.

    Every NAV command with a position (:data:`NAV_POSITION_COMMANDS`) does; so does any other
    command numbered below ``MAV_CMD_NAV_LAST`` that is not known to move to no position of
    its own (:data:`NAV_NOT_FLOWN`), such as a NAV command newer than this table: a mission
    check then checks its leg rather than skipping it.

    Examples
    --------
    >>> flies_to_position(MAV_CMD_NAV_PAYLOAD_PLACE), flies_to_position(MAV_CMD_NAV_ROI)
    (True, False)
    >>> flies_to_position(36), flies_to_position(MAV_CMD_DO_JUMP)  # NAV_ARC_WAYPOINT, a DO
    (True, False)
    """
    if command in NAV_POSITION_COMMANDS:
        return True
    return (
        isinstance(command, int)
        and 0 <= command < MAV_CMD_NAV_LAST
        and command not in NAV_NOT_FLOWN
    )


NAV_COMMAND_NAMES = {
    MAV_CMD_NAV_WAYPOINT: "waypoint",
    MAV_CMD_NAV_LOITER_UNLIM: "loiter",
    MAV_CMD_NAV_LOITER_TURNS: "loiter turns",
    MAV_CMD_NAV_LOITER_TIME: "loiter time",
    MAV_CMD_NAV_RETURN_TO_LAUNCH: "RTL",
    MAV_CMD_NAV_LAND: "land",
    MAV_CMD_NAV_TAKEOFF: "takeoff",
    MAV_CMD_NAV_FOLLOW: "follow",
    MAV_CMD_NAV_LOITER_TO_ALT: "loiter to alt",
    MAV_CMD_NAV_PATHPLANNING: "path planning",
    MAV_CMD_NAV_SPLINE_WAYPOINT: "spline waypoint",
    MAV_CMD_NAV_VTOL_TAKEOFF: "VTOL takeoff",
    MAV_CMD_NAV_VTOL_LAND: "VTOL land",
    MAV_CMD_NAV_PAYLOAD_PLACE: "payload place",
    MAV_CMD_DO_JUMP: "jump",
    MAV_CMD_JUMP_TAG: "jump tag",
    MAV_CMD_DO_JUMP_TAG: "jump to tag",
}
"""Short operator-facing names of the mission commands, for messages."""


def command_name(command) -> str:
    """A NAV command's short name, or ``"command N"`` for any other.

    Examples
    --------
    >>> command_name(22), command_name(183)
    ('takeoff', 'command 183')
    """
    return NAV_COMMAND_NAMES.get(command, f"command {command}")
