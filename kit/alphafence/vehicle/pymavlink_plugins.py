"""The pymavlink link's telemetry, actions, parameters and mission, under MAVSDK's names.

Each class offers the methods of MAVSDK's plugin of the same name that the kit calls, with the
same arguments and values of the same attribute names (:mod:`alphafence.vehicle.values`), as
ArduPilot serves them: modes set with MAV_CMD_DO_SET_MODE (BRAKE for a copter's hold), a goto as
GUIDED plus SET_POSITION_TARGET_GLOBAL_INT, parameters with PARAM_REQUEST_READ / PARAM_SET and
their PARAM_VALUE, AUTO's progress from MISSION_CURRENT; and as PX4 serves them (its modes, a
goto as its reposition, its integer parameters byte-wise).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from operator import itemgetter

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from alphafence.errors import VehicleError
from alphafence.geo.coords import from_e7, to_e7
from alphafence.mavlink import ids
from alphafence.mavlink.param_values import decode, encode
from alphafence.vehicle.px4 import pause, reposition, set_current
from alphafence.vehicle.values import (
    GpsInfo,
    MissionProgress,
    Position,
    StatusText,
    VelocityNed,
    flight_mode,
    mode_set,
    px4_custom_mode,
    px4_flight_mode,
)

PARAM_RETRY_S = 1.0
PARAM_TRIES = 3
IGNORED = ("VX", "VY", "VZ", "AX", "AY", "AZ", "YAW", "YAW_RATE")  # a position target's
POSITION_ONLY = sum(getattr(ids, f"POSITION_TARGET_TYPEMASK_{k}_IGNORE") for k in IGNORED)
NO_MISSION = 0xFFFF  # MISSION_CURRENT's total when the vehicle has no mission (UINT16_MAX)


class CommandRefused(VehicleError):
    """The vehicle answered a command with something other than ACCEPTED."""


def _result_name(result: int) -> str:
    names = {
        v: k for k, v in vars(ids).items() if k.startswith("MAV_RESULT_") and isinstance(v, int)
    }
    return names.get(result, f"MAV_RESULT {result}")


async def _command(vehicle, command, *params):
    result = await vehicle.command_long(command, *params)
    if result != ids.MAV_RESULT_ACCEPTED:
        raise CommandRefused(f"command {command} refused ({_result_name(result)})")


# the fields of GLOBAL_POSITION_INT a position and velocity are made of, in wire order
POSITION_FIELDS = ("lat", "lon", "alt", "relative_alt", "vx", "vy", "vz")
SKIP_FIELDS = ("lat", "lon", "relative_alt", "vx", "vy")  # what a skip is decided on


def _position_velocity(lat, lon, alt, relative_alt, vx, vy, vz):
    """GLOBAL_POSITION_INT's fields (1e-7 degrees, mm, cm/s) as MAVSDK's values."""
    return (
        Position(from_e7(lat), from_e7(lon), alt / 1000.0, relative_alt / 1000.0),
        VelocityNed(vx / 100.0, vy / 100.0, vz / 100.0),
    )


def _armed(m) -> bool:
    return bool(m.base_mode & ids.MAV_MODE_FLAG_SAFETY_ARMED)


def _gps_info(m) -> GpsInfo:
    return GpsInfo(int(m.satellites_visible), int(m.fix_type))


class Telemetry:
    """``subscribe_*`` streams of the autopilot's own messages, and their rates."""

    def __init__(self, vehicle):
        self.v = vehicle

    async def _own(self, name):
        async for msg in self.v.bus.stream(name):
            if self.v.from_autopilot(msg):
                yield msg

    async def subscribe_position(self):
        """GLOBAL_POSITION_INT as :class:`~alphafence.vehicle.values.Position`."""
        async for m in self._own("GLOBAL_POSITION_INT"):
            yield Position(from_e7(m.lat), from_e7(m.lon), m.alt / 1000.0, m.relative_alt / 1000.0)

    async def subscribe_velocity_ned(self):
        """GLOBAL_POSITION_INT's velocity as :class:`~alphafence.vehicle.values.VelocityNed`."""
        async for m in self._own("GLOBAL_POSITION_INT"):
            yield VelocityNed(m.vx / 100.0, m.vy / 100.0, m.vz / 100.0)

    async def subscribe_position_velocity(self):
        """Both from each GLOBAL_POSITION_INT, as ``(Position, VelocityNed)`` (one stream where
        MAVSDK has two)."""
        async for m in self._own("GLOBAL_POSITION_INT"):
            yield _position_velocity(m.lat, m.lon, m.alt, m.relative_alt, m.vx, m.vy, m.vz)

    @contextlib.contextmanager
    def listen_position_velocity(self, callback, skip=None):
        """``with telemetry.listen_position_velocity(callback):`` ``callback((Position,
        VelocityNed))`` for each GLOBAL_POSITION_INT of the autopilot, called as the message is
        parsed: no task wakes up for it (the monitor's feed at 10-50 Hz). While nothing else
        follows GLOBAL_POSITION_INT, its frames are decoded straight to these values
        (:mod:`alphafence.vehicle.fast_frames`), not through pymavlink's message objects.

        ``skip(lat, lon, relative_alt, vx, vy) -> bool``, if given, sees those fields of each
        such frame first, as the wire has them (1e-7 degrees, mm, cm/s); a position it returns
        True for is taken as it is, and ``callback`` is not called for it (the monitor's
        positions that need no check: no value is built for them)."""
        v = self.v

        def handle(m) -> bool:
            if v.from_autopilot(m):
                callback(_position_velocity(m.lat, m.lon, m.alt, m.relative_alt, m.vx, m.vy, m.vz))
            return True

        def fast(fields, system, component):
            if (system, component) != v.target:
                return
            if skip is None or not skip(*lean(fields)):
                callback(_position_velocity(*pick(fields)))

        name, cls = "GLOBAL_POSITION_INT", mavlink.MAVLink_global_position_int_message
        with v.bus.subscribe(name, maxsize=1, handle=handle):
            with v.link.fast(cls, fast, lambda: v.bus.alone(name)) as decoder:
                pick = itemgetter(*(decoder.index[f] for f in POSITION_FIELDS))
                lean = itemgetter(*(decoder.index[f] for f in SKIP_FIELDS))
                yield

    def _mode(self, m):
        if self.v.autopilot == "px4":
            return px4_flight_mode(m.custom_mode)
        return flight_mode(m.type, m.custom_mode)

    async def subscribe_flight_mode(self):
        """Each HEARTBEAT's mode as :class:`~alphafence.vehicle.values.FlightMode`."""
        async for m in self._own("HEARTBEAT"):
            yield self._mode(m)

    async def subscribe_armed(self):
        """Each HEARTBEAT's safety-armed flag."""
        async for m in self._own("HEARTBEAT"):
            yield _armed(m)

    def _listen(self, name, value, callback):
        """``callback(value(msg))`` for each of the autopilot's ``name`` messages, as parsed."""

        def handle(m) -> bool:
            if self.v.from_autopilot(m):
                callback(value(m))
            return True

        return self.v.bus.subscribe(name, maxsize=1, handle=handle)

    def listen_flight_mode(self, callback):
        """``with telemetry.listen_flight_mode(callback):`` each HEARTBEAT's mode, as parsed."""
        return self._listen("HEARTBEAT", self._mode, callback)

    def listen_armed(self, callback):
        """``with telemetry.listen_armed(callback):`` each HEARTBEAT's armed flag, as parsed."""
        return self._listen("HEARTBEAT", _armed, callback)

    def listen_gps_info(self, callback):
        """``with telemetry.listen_gps_info(callback):`` each GPS_RAW_INT, as parsed."""
        return self._listen("GPS_RAW_INT", _gps_info, callback)

    async def subscribe_gps_info(self):
        """GPS_RAW_INT as :class:`~alphafence.vehicle.values.GpsInfo`."""
        async for m in self._own("GPS_RAW_INT"):
            yield _gps_info(m)

    async def subscribe_status_text(self):
        """The autopilot's STATUSTEXTs as :class:`~alphafence.vehicle.values.StatusText`."""
        async for m in self.v.status_texts():
            yield StatusText(int(m.severity), str(m.text))

    async def _rate(self, message_id, hz):
        await _command(self.v, ids.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, 1e6 / hz)

    async def set_rate_position(self, hz: float):
        """GLOBAL_POSITION_INT at ``hz`` (CommandRefused when the vehicle says no)."""
        await self._rate(ids.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, hz)

    async def set_rate_velocity_ned(self, hz: float):
        """Velocity comes with the position: the same message's rate."""
        await self._rate(ids.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, hz)


class Action:
    """Mode changes and commands, as ArduPilot takes them."""

    def __init__(self, vehicle):
        self.v = vehicle
        self.takeoff_altitude_m = 2.5  # MAVSDK's default

    async def set_mode(self, custom_mode: int):
        """MAV_CMD_DO_SET_MODE with ArduPilot's ``custom_mode`` number."""
        await _command(
            self.v, ids.MAV_CMD_DO_SET_MODE, ids.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode
        )

    async def _px4(self, name: str):
        """MAV_CMD_DO_SET_MODE with PX4's main and sub mode of ``name``."""
        c, flag = px4_custom_mode(name), ids.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        await _command(self.v, ids.MAV_CMD_DO_SET_MODE, flag, c >> 16 & 0xFF, c >> 24 & 0xFF)

    async def hold(self):
        """Stop where it is: BRAKE (copter), LOITER (plane), HOLD (rover); on PX4 Hold where
        it is (:func:`~alphafence.vehicle.px4.pause`)."""
        if self.v.autopilot == "px4":
            return await pause(self.v)
        await self.set_mode(mode_set(self.v.mav_type).hold)

    async def return_to_launch(self):
        """RTL (PX4's Return)."""
        if self.v.autopilot == "px4":
            return await self._px4("AUTO.RTL")
        await self.set_mode(mode_set(self.v.mav_type).rtl)

    async def land(self):
        """LAND (a plane: QLAND; a rover cannot; PX4's Land)."""
        if self.v.autopilot == "px4":
            return await self._px4("AUTO.LAND")
        land = mode_set(self.v.mav_type).land
        if land is None:
            raise CommandRefused("this vehicle has no land mode")
        await self.set_mode(land)

    async def goto_location(self, lat, lon, alt_amsl_m, yaw_deg=math.nan):
        """GUIDED, then fly to ``(lat, lon)`` at ``alt_amsl_m`` (the heading is kept); on PX4
        MAV_CMD_DO_REPOSITION (it flies there in Hold), as MAVSDK sends it."""
        if self.v.autopilot == "px4":
            return await reposition(self.v, lat, lon, alt_amsl_m, yaw_deg)
        await self.set_mode(mode_set(self.v.mav_type).guided)
        sysid, compid = self.v.target
        self.v.link.send(
            self.v.link.mav.set_position_target_global_int_encode(
                0, sysid, compid, ids.MAV_FRAME_GLOBAL_INT, POSITION_ONLY,
                to_e7(lat), to_e7(lon), float(alt_amsl_m), 0, 0, 0, 0, 0, 0, 0, 0,
            )
        )  # fmt: skip

    async def arm(self):
        """Arm (CommandRefused when a pre-arm check fails)."""
        await _command(self.v, ids.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    async def set_takeoff_altitude(self, alt_m: float):
        """The height above home :meth:`takeoff` climbs to."""
        self.takeoff_altitude_m = float(alt_m)

    async def takeoff(self):
        """GUIDED, then MAV_CMD_NAV_TAKEOFF to the takeoff altitude (PX4: the command alone,
        the altitude AMSL in it)."""
        if self.v.autopilot == "px4":  # (a parameter set first may reach its navigator late)
            async for p in self.v.telemetry.subscribe_position():
                home = p.absolute_altitude_m - p.relative_altitude_m
                break
            alt = home + self.takeoff_altitude_m
            return await _command(self.v, ids.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 6, alt)
        await self.set_mode(mode_set(self.v.mav_type).guided)
        await _command(self.v, ids.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, self.takeoff_altitude_m)

    async def set_current_speed(self, speed_m_s: float):
        """MAV_CMD_DO_CHANGE_SPEED (ground speed)."""
        await _command(self.v, ids.MAV_CMD_DO_CHANGE_SPEED, 1, speed_m_s, -1)


class Param:
    """Parameters by name, read back from the vehicle's PARAM_VALUE (PX4's integers byte-wise:
    :mod:`alphafence.mavlink.param_values`)."""

    def __init__(self, vehicle):
        self.v = vehicle

    async def _exchange(self, name: str, make) -> float:
        key = name.encode()[:16]
        with self.v.bus.subscribe("PARAM_VALUE", maxsize=64) as queue:
            for _ in range(PARAM_TRIES):
                self.v.link.send(make(key))
                deadline = asyncio.get_running_loop().time() + PARAM_RETRY_S
                while (left := deadline - asyncio.get_running_loop().time()) > 0:
                    try:
                        msg = await asyncio.wait_for(queue.get(), left)
                    except asyncio.TimeoutError:
                        break
                    if self.v.from_autopilot(msg) and msg.param_id == name:
                        return decode(msg.param_value, msg.param_type, self._bytewise)
        raise TimeoutError(f"the vehicle did not answer for parameter {name}")

    def _read(self, name):
        sysid, compid = self.v.target
        mav = self.v.link.mav
        return self._exchange(
            name, lambda key: mav.param_request_read_encode(sysid, compid, key, -1)
        )

    def _write(self, name, value, kind):
        sysid, compid = self.v.target
        mav = self.v.link.mav
        wire = encode(value, kind, self._bytewise)
        return self._exchange(
            name, lambda key: mav.param_set_encode(sysid, compid, key, wire, kind)
        )

    @property
    def _bytewise(self) -> bool:  # PX4 copies an integer's bytes into the float
        return self.v.autopilot == "px4"

    async def get_param_int(self, name: str) -> int:
        """The parameter's value as an integer."""
        return int(round(await self._read(name)))

    async def get_param_float(self, name: str) -> float:
        """The parameter's value."""
        return await self._read(name)

    async def set_param_int(self, name: str, value: int) -> None:
        """Set it; returns once the vehicle answers with the parameter."""
        await self._write(name, int(value), ids.MAV_PARAM_TYPE_INT32)

    async def set_param_float(self, name: str, value: float) -> None:
        """Set it; returns once the vehicle answers with the parameter."""
        await self._write(name, value, ids.MAV_PARAM_TYPE_REAL32)


class MissionRaw:
    """The mission: upload, download, AUTO's progress, where AUTO resumes."""

    def __init__(self, vehicle):
        self.v = vehicle

    async def upload_mission(self, items) -> None:
        """Upload ``items`` (:class:`~alphafence.vehicle.values.RawItem`, home first) as the
        mission (TransferFailed on failure)."""
        await self.v.mission.upload(items, ids.MAV_MISSION_TYPE_MISSION)

    async def download_mission(self) -> list:
        """The mission's raw items (TransferFailed on failure)."""
        return await self.v.mission.download(ids.MAV_MISSION_TYPE_MISSION)

    async def subscribe_mission_progress(self):
        """AUTO's progress as MAVSDK reports it, on each change
        (:class:`~alphafence.vehicle.values.MissionProgress`).

        ``current``: the item after the last MISSION_ITEM_REACHED (ArduPilot sends those on
        every link) or MISSION_CURRENT's item (streamed only when asked for; after the last
        item it stays on the reached one). ``total``: the mission's items (ArduPilot's with
        home): the count of this link's last upload or download of it, else MISSION_CURRENT's
        total (+ 1 on ArduPilot, whose total leaves home out; 65535 is no mission), else 0.
        """
        reached, current, heard, last = -1, None, 0, None
        home = 0 if self.v.autopilot == "px4" else 1
        async for m in self.v.bus.stream("MISSION_CURRENT", "MISSION_ITEM_REACHED"):
            if not self.v.from_autopilot(m):
                continue
            if m.get_type() == "MISSION_ITEM_REACHED":
                reached = int(m.seq)
                current = reached + 1
            else:
                n = int(getattr(m, "total", 0) or 0)  # 0: no total (an older MAVLink)
                heard = 0 if n == NO_MISSION else n + home if n else heard
                if int(m.seq) != reached:
                    current = int(m.seq)
            total = self.v.mission.counts.get(ids.MAV_MISSION_TYPE_MISSION, heard)
            if current is not None and (current, total) != last:
                last = (current, total)
                yield MissionProgress(current, total)

    async def set_current_mission_item(self, index: int):
        """Make item ``index`` the one AUTO flies to next (on PX4 :func:`~.px4.set_current`)."""
        if self.v.autopilot == "px4":
            return await set_current(self.v, index)
        await _command(self.v, ids.MAV_CMD_DO_SET_MISSION_CURRENT, index)

    async def start_mission(self):
        """AUTO, then MAV_CMD_MISSION_START, as MAVSDK sends them: a copter armed on the ground
        takes off only after MISSION_START (it sets "auto armed"; AUTO alone waits for
        throttle, and ArduCopter disarms after DISARM_DELAY). On PX4 its Mission mode alone,
        as MAVSDK sends it (PX4 would take MISSION_START's first item, 0, as the current one)."""
        if self.v.autopilot == "px4":
            return await self.v.action._px4("AUTO.MISSION")
        await self.v.action.set_mode(mode_set(self.v.mav_type).auto)
        await _command(self.v, ids.MAV_CMD_MISSION_START, 0, 0)
