"""The async companion monitor: MAVSDK telemetry in, the engine's decisions out.

Telemetry subscriptions only update the latest state; a checker wakes on every new position
and at least every 0.1 s; alerts (STATUSTEXT to the ground station) and actions (brake, RTL,
land) run as their own tasks; the event log is written by its own task off the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from datetime import datetime, timezone

from kit.monitor.engine import Engine, Sample, alert_text

TICK_S = 0.1


class EventLog:
    """JSON lines, appended by a background task (file I/O never blocks the loop)."""

    def __init__(self, path=None, echo=None):
        self.path = path
        self.echo = echo
        self.queue: asyncio.Queue = asyncio.Queue()
        self.task = asyncio.create_task(self._write()) if path else None
        self.events = []

    def put(self, event):
        self.events.append(event)
        if self.echo:
            self.echo(event)
        if self.task:
            self.queue.put_nowait(json.dumps(event, separators=(",", ":")))

    async def _write(self):
        while True:
            lines = [await self.queue.get()]
            while not self.queue.empty():
                lines.append(self.queue.get_nowait())
            await asyncio.to_thread(_append, self.path, lines)

    async def close(self):
        if self.task:
            while not self.queue.empty():
                await asyncio.sleep(0.01)
            await asyncio.sleep(0.05)
            self.task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.task


def parse_adsb(fields_json):
    """An ADSB_VEHICLE message's fields (MAVSDK mavlink_direct JSON) -> Engine.aircraft kwargs,
    or None when it carries no usable position."""
    try:
        f = json.loads(fields_json)
        lat, lon = f["lat"] / 1e7, f["lon"] / 1e7
        alt = f["altitude"] / 1000.0
        speed = f.get("hor_velocity", 0) / 100.0
        heading = math.radians(f.get("heading", 0) / 100.0)
        climb = f.get("ver_velocity", 0) / 100.0
        callsign = str(f.get("callsign", "")).strip("\x00 ")
        key = f.get("ICAO_address")
    except (ValueError, KeyError, TypeError):
        return None
    if key is None or not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
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
    """Another MAVLink system's GLOBAL_POSITION_INT -> Engine.aircraft kwargs, or None."""
    try:
        f = json.loads(fields_json)
        lat, lon = f["lat"] / 1e7, f["lon"] / 1e7
        out = {
            "key": f"mavlink/{int(system_id)}",
            "lat": lat,
            "lon": lon,
            "alt_amsl_m": f["alt"] / 1000.0,
            "ve": f.get("vy", 0) / 100.0,
            "vn": f.get("vx", 0) / 100.0,
            "vu": -f.get("vz", 0) / 100.0,
            "callsign": f"MAV{int(system_id)}",
        }
    except (ValueError, KeyError, TypeError):
        return None
    if not (abs(lat) <= 90 and abs(lon) <= 180) or (lat == 0 and lon == 0):
        return None
    return out


def _append(path, lines):
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


class Monitor:
    def __init__(self, vehicle, fences, options, log: EventLog, rate_hz: float = 10.0, record=None):
        self.vehicle = vehicle
        self.record = record  # a list that receives every telemetry sample (for replay tests)
        self.engine = Engine(fences, options)
        self.log = log
        self.rate_hz = rate_hz
        self.latest = {"position": None, "velocity": None, "mode": None, "armed": None, "gps": None}
        self.new_position = asyncio.Event()
        self.tasks = []
        self.pending = set()
        self._clock_t = -math.inf

    async def run(self, stop: asyncio.Event):
        tel = self.vehicle.telemetry
        for setter in (tel.set_rate_position, tel.set_rate_velocity_ned):
            with contextlib.suppress(Exception):
                await setter(self.rate_hz)
        self.tasks = [
            asyncio.create_task(self._follow(tel.subscribe_position(), "position", wake=True)),
            asyncio.create_task(self._follow(tel.subscribe_velocity_ned(), "velocity")),
            asyncio.create_task(self._follow(tel.subscribe_flight_mode(), "mode")),
            asyncio.create_task(self._follow(tel.subscribe_armed(), "armed")),
            asyncio.create_task(self._follow(tel.subscribe_gps_info(), "gps")),
            asyncio.create_task(self._adsb()),
        ]
        if self.engine.options.mavlink_traffic:
            # every GLOBAL_POSITION_INT on the link, the vehicle's own at the telemetry rate
            # included, crosses into Python: opt-in, for links that carry other aircraft
            self.tasks.append(asyncio.create_task(self._other_systems()))
        try:
            while not stop.is_set():
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self.new_position.wait(), TICK_S)
                events = []
                if self.new_position.is_set():
                    self.new_position.clear()
                    sample = self._sample()
                    if sample is not None:
                        if self.record is not None:
                            self.record.append(sample)
                        events += self.engine.step(sample)
                events += self.engine.tick(time.monotonic())
                if time.monotonic() - self._clock_t > 1.0:  # ED-269 time windows
                    self._clock_t = time.monotonic()
                    self.engine.fences.set_time(datetime.now(timezone.utc))
                for e in events:
                    self._handle(e)
        finally:
            for t in self.tasks + list(self.pending):
                t.cancel()
            for t in self.tasks + list(self.pending):
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await t

    async def _follow(self, stream, key, wake=False):
        async for value in stream:
            self.latest[key] = (time.monotonic(), value)
            if wake:
                self.new_position.set()

    async def _adsb(self):
        """ADSB_VEHICLE reports (forwarded by ArduPilot from its ADS-B receiver) -> traffic."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        try:
            stream = MavlinkDirectAsync(self.vehicle.system).subscribe_message("ADSB_VEHICLE")
            async for message in stream:
                report = parse_adsb(message.fields_json)
                if report is not None:
                    self.engine.aircraft(t=time.monotonic(), **report)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # no ADS-B is an event, never a crash
            self.log.put(
                {"time": round(time.monotonic(), 3), "event": "adsb_unavailable", "error": str(exc)}
            )

    async def _other_systems(self):
        """Other MAVLink systems on the link (other drones, a chase aircraft) -> traffic."""
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        try:
            own = int(await self.vehicle.system.get_system_id())
        except Exception:
            own = 1  # ArduPilot's default SYSID_THISMAV
        try:
            stream = MavlinkDirectAsync(self.vehicle.system).subscribe_message(
                "GLOBAL_POSITION_INT"
            )
            async for message in stream:
                if message.system_id in (own, 0):
                    continue
                report = parse_global_position(message.system_id, message.fields_json)
                if report is not None:
                    self.engine.aircraft(t=time.monotonic(), **report)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "traffic_link_unavailable",
                    "error": str(exc),
                }
            )

    def _sample(self):
        pos = self.latest["position"]
        if pos is None:
            return None
        t, p = pos
        vel = self.latest["velocity"]
        vn, ve = (vel[1].north_m_s, vel[1].east_m_s) if vel else (0.0, 0.0)
        mode = self.latest["mode"]
        armed = self.latest["armed"]
        return Sample(
            t,
            p.latitude_deg,
            p.longitude_deg,
            p.relative_altitude_m,
            vn,
            ve,
            mode[1].name if mode else None,
            armed[1] if armed else None,
            alt_amsl_m=p.absolute_altitude_m,
            gps_fix=int(self.latest["gps"][1].fix_type) if self.latest["gps"] else None,
            vd=vel[1].down_m_s if vel else 0.0,
        )

    def _handle(self, event):
        self.log.put(event)
        text = alert_text(event)
        if text:
            self._spawn(self._alert(text, event))
        if event["event"] == "action":
            self._spawn(self._act(event["action"]))

    def _spawn(self, coro):
        task = asyncio.create_task(coro)
        self.pending.add(task)
        task.add_done_callback(self.pending.discard)

    async def _alert(self, text, event):
        from mavsdk.asyncio.plugins.server_utility import ServerUtilityAsync
        from mavsdk.plugins.server_utility import StatusTextType

        severity = (
            StatusTextType.CRITICAL
            if event.get("level") in ("IMMINENT", "BREACH")
            else StatusTextType.WARNING
        )
        try:
            await ServerUtilityAsync(self.vehicle.system).send_status_text(severity, text)
        except Exception as exc:  # an alert that cannot be sent is logged, never fatal
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "alert_failed",
                    "text": text,
                    "error": str(exc),
                }
            )

    async def _act(self, action):
        act = self.vehicle.action
        try:
            if action == "brake":
                await act.hold()
            elif action == "rtl":
                await act.return_to_launch()
            elif action == "land":
                await act.land()
            self.log.put(
                {"time": round(time.monotonic(), 3), "event": "action_done", "action": action}
            )
        except Exception as exc:
            self.log.put(
                {
                    "time": round(time.monotonic(), 3),
                    "event": "action_failed",
                    "action": action,
                    "error": str(exc),
                }
            )


async def run_monitor(
    url,
    fences,
    options,
    log_path=None,
    stop: asyncio.Event | None = None,
    echo=None,
    timeout: float = 10.0,
):
    from kit.vehicle.link import open_vehicle

    stop = stop or asyncio.Event()
    log = EventLog(log_path, echo)
    try:
        async with open_vehicle(url, timeout) as vehicle:
            monitor = Monitor(vehicle, fences, options, log)
            await monitor.run(stop)
            return monitor
    finally:
        await log.close()
