"""Where the monitor's inputs come from: one async generator per stream of the vehicle link.

A feed yields values as they arrive and does nothing else with them; the runner follows each
in a task of its own and hands every value, with its arrival time, to where it belongs (a
:class:`Feed`'s ``deliver``: the latest telemetry, the engine's traffic, the re-route's goals).

* the telemetry streams (:data:`TELEMETRY`: position, velocity, flight mode, armed, GPS):
  the link's ``subscribe_*`` generators (MAVSDK's names, on either link), as they are; :func:`latest_sample` makes the
  engine's input of their latest values;
* :func:`adsb` - ADSB_VEHICLE reports (forwarded by ArduPilot from its ADS-B receiver);
* :func:`other_systems` - other MAVLink systems' GLOBAL_POSITION_INT, as traffic too;
* :func:`guided_targets` - the vehicle's GUIDED target (POSITION_TARGET_GLOBAL_INT);
* :func:`mission_progress` - AUTO's current item; :func:`download_mission` the mission.

The parsers (:func:`parse_adsb`, :func:`parse_global_position`) treat what the vehicle sends
like a file: anything missing, out of range or not finite is dropped, never raised.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

from alphafence.geo.coords import from_e7_float
from alphafence.mavlink import ids
from alphafence.monitor.engine import Sample
from alphafence.vehicle.values import fields_of, mode_name

TELEMETRY = {
    "position": "subscribe_position",
    "velocity": "subscribe_velocity_ned",
    "mode": "subscribe_flight_mode",
    "armed": "subscribe_armed",
    "gps": "subscribe_gps_info",
}
"""The telemetry streams whose latest value the monitor keeps: key -> the link's method."""


@dataclass
class Feed:
    """One stream the monitor follows.

    Attributes
    ----------
    open : callable
        ``open()`` -> the async iterator of values (called when the monitor runs).
    deliver : callable
        ``deliver(t, value)`` with each value and its arrival time (``time.monotonic()``).
    unavailable : str or None
        The event to log when the stream fails (with its error); None: the failure ends the
        feed's task (a telemetry stream: the runner reports ``telemetry_task_ended``).
    split : tuple of str or None
        A feed of several streams at once: each value is a tuple of their values, in this
        order (observers are told of each under its own name).
    then : callable or None
        Called after each value has been delivered and the observers told (the runner's
        check of a position that came with its velocity).
    listen : callable or None
        ``listen(callback)`` -> a context manager during which the link calls
        ``callback(value)`` with each value as it is parsed (no task wakes up: at 10 Hz the
        wake-ups are most of the cost); ``open`` is the same stream for links without it.
    """

    open: Callable[[], AsyncIterator]
    deliver: Callable[[float, object], None]
    unavailable: str | None = None
    split: tuple[str, ...] | None = None  # each value a tuple of these streams' values
    then: Callable[[], None] | None = None  # called after each value is delivered and observed
    listen: Callable | None = None  # listen(callback) -> context: values pushed as they come
    # skip(lat, lon, relative_alt, vx, vy) -> bool, as the wire has them (1e-7 degrees, mm,
    # cm/s): given to a listen that takes it, a position it returns True for is not delivered
    skip: Callable | None = None


def telemetry_feed(vehicle, key: str, deliver) -> Feed:
    """The :class:`Feed` of telemetry stream ``key`` (one of :data:`TELEMETRY`): pushed as
    parsed where the link can (its ``listen_*``, the pymavlink link's), else followed."""
    method = TELEMETRY[key]
    telemetry = getattr(vehicle, "telemetry", None)
    listen = getattr(telemetry, method.replace("subscribe_", "listen_", 1), None)
    return Feed(lambda: getattr(vehicle.telemetry, method)(), deliver, listen=listen)


def telemetry_feeds(vehicle, keep) -> dict:
    """The feeds of every :data:`TELEMETRY` stream, named ``telemetry:<key>``.

    A link whose position and velocity come in one message (the pymavlink link's
    ``subscribe_position_velocity``: both from GLOBAL_POSITION_INT) feeds them together, one
    task and one wake-up per position instead of two, and the position never meets the
    previous message's velocity.

    Parameters
    ----------
    vehicle : Vehicle
        The link.
    keep : callable
        ``keep(key)`` -> the ``deliver(t, value)`` of that stream.
    """
    both = getattr(getattr(vehicle, "telemetry", None), "subscribe_position_velocity", None)
    feeds = {}
    for key in TELEMETRY:
        if both is not None and key in ("position", "velocity"):
            continue
        feeds[f"telemetry:{key}"] = telemetry_feed(vehicle, key, keep(key))
    if both is not None:
        position, velocity = keep("position"), keep("velocity")

        def deliver(t, value):
            velocity(t, value[1])
            position(t, value[0])

        listen = getattr(vehicle.telemetry, "listen_position_velocity", None)
        feeds["telemetry:position"] = Feed(
            both, deliver, split=("position", "velocity"), listen=listen
        )
    return feeds


async def set_rates(telemetry, rate_hz: float) -> None:
    """Ask for position and velocity at ``rate_hz`` (a vehicle that refuses keeps its rate).
    A link whose velocity comes with the position (``subscribe_position_velocity``) asks once."""
    setters = [telemetry.set_rate_position]
    if not hasattr(telemetry, "subscribe_position_velocity"):
        setters.append(telemetry.set_rate_velocity_ned)
    for setter in setters:
        with contextlib.suppress(Exception):
            await setter(rate_hz)


def latest_sample(latest: dict, autopilot: str = "ardupilot") -> Sample | None:
    """The engine's input from the latest telemetry values, or None before the first position.

    Parameters
    ----------
    latest : dict
        ``{key: (arrival time, value) or None}`` for every key of :data:`TELEMETRY`.
    autopilot : str
        The vehicle's (``Vehicle.autopilot``): how its modes are named.

    Returns
    -------
    Sample or None
        At the position's arrival time; a missing velocity counts as zero, a missing mode,
        armed state or GPS fix as unknown; the mode as the autopilot names it
        (:func:`~alphafence.vehicle.values.mode_name`).
    """
    pos = latest["position"]
    if pos is None:
        return None
    t, p = pos
    vel = latest["velocity"]
    vn, ve = (vel[1].north_m_s, vel[1].east_m_s) if vel else (0.0, 0.0)
    mode = latest["mode"]
    armed = latest["armed"]
    return Sample(
        t,
        p.latitude_deg,
        p.longitude_deg,
        p.relative_altitude_m,
        vn,
        ve,
        mode_name(mode[1].name, autopilot) if mode else None,
        armed[1] if armed else None,
        alt_amsl_m=p.absolute_altitude_m,
        gps_fix=int(latest["gps"][1].fix_type) if latest["gps"] else None,
        vd=vel[1].down_m_s if vel else 0.0,
    )


async def adsb(vehicle):
    """ADSB_VEHICLE reports (forwarded by ArduPilot from its ADS-B receiver).

    Yields
    ------
    dict
        Each usable report as :meth:`Engine.aircraft <alphafence.monitor.engine.Engine.aircraft>`
        keyword arguments (without ``t``).
    """
    async for message in vehicle.messages("ADSB_VEHICLE"):
        report = parse_adsb(message.fields)
        if report is not None:
            yield report


async def other_systems(vehicle):
    """Other MAVLink systems on the link (other drones, a chase aircraft) as traffic.

    Every GLOBAL_POSITION_INT on the link, the vehicle's own at the telemetry rate included,
    crosses into Python: the runner follows this only with ``mavlink_traffic``.

    Yields
    ------
    dict
        Each usable report of another system, as :func:`parse_global_position` makes it.
    """
    own = await vehicle.system_id()
    async for message in vehicle.messages("GLOBAL_POSITION_INT"):
        if message.system_id in (own, 0):
            continue
        report = parse_global_position(message.system_id, message.fields)
        if report is not None:
            yield report


async def guided_targets(vehicle, hz: float):
    """The vehicle's GUIDED target, which ArduPilot sends only when asked (this asks for it at
    ``hz``) and only while it flies to a position in GUIDED.

    Yields
    ------
    tuple
        ``(lon, lat)`` of each POSITION_TARGET_GLOBAL_INT from the vehicle that carries one.
    """
    from alphafence.monitor.reroute import parse_position_target

    own = await vehicle.system_id()
    await vehicle.command_long(
        ids.MAV_CMD_SET_MESSAGE_INTERVAL, ids.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT, 1e6 / hz
    )
    async for message in vehicle.messages("POSITION_TARGET_GLOBAL_INT"):
        if message.system_id not in (own, 0):
            continue
        target = parse_position_target(message.fields)
        if target is not None:
            yield target


async def mission_progress(mission_raw):
    """AUTO's progress through the mission.

    Yields
    ------
    tuple of int
        ``(current item, total items)``, as MAVSDK reports them.
    """
    async for p in mission_raw.subscribe_mission_progress():
        yield (int(p.current), int(p.total))


async def download_mission(mission_raw, timeout: float) -> list:
    """The vehicle's mission (MAVSDK ``mission_raw`` items), within ``timeout`` seconds.

    Raises
    ------
    asyncio.TimeoutError
        When the download takes longer; MAVSDK's own errors as they are.
    """
    return list(await asyncio.wait_for(mission_raw.download_mission(), timeout))


def _num(fields, key, default=None) -> float:
    """A finite number from a message's fields (ValueError when missing or not finite)."""
    value = fields.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(key)
    value = float(value)  # OverflowError for an absurd integer
    if not math.isfinite(value):
        raise ValueError(key)
    return value


def parse_adsb(fields_json):
    """An ADSB_VEHICLE message's fields (a dict, or JSON text) -> Engine.aircraft kwargs,
    or None when it carries no usable position (missing, out of range, not finite).

    Parameters
    ----------
    fields_json : dict or str
        The message's fields, or them as JSON.

    Returns
    -------
    dict or None
        ``key`` (ICAO address), ``lat``, ``lon``, ``alt_amsl_m``, ``ve``, ``vn``, ``vu``
        (m/s) and ``callsign``.
    """
    try:
        f = fields_of(fields_json)
        lat, lon = from_e7_float(_num(f, "lat")), from_e7_float(_num(f, "lon"))
        alt = _num(f, "altitude") / 1000.0
        speed = _num(f, "hor_velocity", 0) / 100.0
        heading = math.radians(_num(f, "heading", 0) / 100.0)
        climb = _num(f, "ver_velocity", 0) / 100.0
        callsign = str(f.get("callsign", "")).strip("\x00 ")[:16]
        key = f.get("ICAO_address")
        if key is None or isinstance(key, dict | list | float):
            return None
    except (ValueError, KeyError, TypeError, OverflowError, AttributeError):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return {
        "key": key,
        "lat": lat,
        "lon": lon,
        "alt_amsl_m": alt,
        "ve": speed * math.sin(heading),
        "vn": speed * math.cos(heading),
        "vu": climb,
        "callsign": callsign,
    }


def parse_global_position(system_id, fields_json):
    """Another MAVLink system's GLOBAL_POSITION_INT -> Engine.aircraft kwargs, or None.

    Parameters
    ----------
    system_id : int
        The sender: the report's key is ``mavlink/<system_id>``, its callsign ``MAV<id>``.
    fields_json : dict or str
        The message's fields, or them as JSON.
    """
    try:
        f = fields_of(fields_json)
        lat, lon = from_e7_float(_num(f, "lat")), from_e7_float(_num(f, "lon"))
        out = {
            "key": f"mavlink/{int(system_id)}",
            "lat": lat,
            "lon": lon,
            "alt_amsl_m": _num(f, "alt") / 1000.0,
            "ve": _num(f, "vy", 0) / 100.0,
            "vn": _num(f, "vx", 0) / 100.0,
            "vu": -_num(f, "vz", 0) / 100.0,
            "callsign": f"MAV{int(system_id)}",
        }
    except (ValueError, KeyError, TypeError, OverflowError, AttributeError):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return out
