"""What the monitor sends to the vehicle: actions (brake, RTL, land, the re-route's gotos and
the mission's resumption) and alerts (STATUSTEXT to the ground station), through whichever
vehicle link is open (:class:`~alphafence.vehicle.base.Vehicle`).

Commands go out one at a time (:meth:`Commands.send`), each finishing even when the task that
sent it is cancelled: a brake or RTL is never overtaken by a re-route's goto. A command or
alert that fails is an event in the log, never an exception out of the monitor.
"""

from __future__ import annotations

import asyncio

from alphafence.mavlink import ids
from alphafence.monitor.events import new_event
from alphafence.vehicle.px4 import pause

SEVERE_LEVELS = ("IMMINENT", "BREACH")  # their alerts are CRITICAL, the others WARNING


class Commands:
    """The monitor's commands to one vehicle.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle link (``action``, ``mission_raw``, ``send_status_text``).
    log : EventLog
        Where ``action_done``, ``action_failed`` and ``alert_failed`` go.
    spawn : callable
        ``spawn(coroutine)`` -> a task the monitor cancels when it stops.
    """

    def __init__(self, vehicle, log, spawn):
        self.vehicle = vehicle
        self.log = log
        self.spawn = spawn
        self._lock = asyncio.Lock()

    async def send(self, call, *args):
        """``await call(*args)`` (a vehicle command) after any command still under way, in a
        task of its own: cancelling the caller does not cut it off halfway (a goto is a mode change
        followed by a position target), and the next command waits for it.

        Returns
        -------
        object
            What ``call`` returned; its exception is raised here.
        """

        async def locked():
            async with self._lock:
                return await call(*args)

        task = self.spawn(locked())
        # its outcome is the caller's; retrieved here too in case the caller is gone
        task.add_done_callback(lambda t: t.cancelled() or t.exception())
        return await asyncio.shield(task)

    async def act(self, action: str, at=None) -> None:
        """Command ``action`` (``"brake"``: MAVSDK's hold, ArduPilot's BRAKE, on PX4 a stop
        where it is, :func:`~alphafence.vehicle.px4.pause`; ``"rtl"``; ``"land"``) and log
        ``action_done`` or ``action_failed``. ``at``: ``(lat, lon, alt_amsl_m)`` where the
        vehicle was last seen (PX4's stop through MAVSDK goes there)."""
        act = self.vehicle.action
        try:
            if action == "brake" and getattr(self.vehicle, "autopilot", "") == "px4":
                await self.send(pause, self.vehicle, at)
            elif action == "brake":
                await self.send(act.hold)
            elif action == "rtl":
                await self.send(act.return_to_launch)
            elif action == "land":
                await self.send(act.land)
            self.log.put(new_event("action_done", action=action))
        except Exception as exc:
            self.log.put(new_event("action_failed", action=action, error=str(exc)))

    async def goto(self, lat: float, lon: float, alt_amsl_m: float) -> None:
        """Fly to ``(lat, lon)`` at ``alt_amsl_m`` in GUIDED, heading unchanged."""
        await self.send(self.vehicle.action.goto_location, lat, lon, alt_amsl_m, float("nan"))

    async def resume_mission(self, item: int) -> None:
        """Back to AUTO at mission item ``item``; ``action_failed`` if the vehicle refuses
        (it then holds where it is, in GUIDED)."""
        mission = self.vehicle.mission_raw
        try:
            await self.send(mission.set_current_mission_item, item)
            await self.send(mission.start_mission)
        except Exception as exc:
            self.log.put(
                new_event("action_failed", action="resume_mission", item=item, error=str(exc))
            )

    async def alert(self, text: str, event: dict) -> None:
        """Send ``text`` to the ground station as a STATUSTEXT, CRITICAL for an IMMINENT or
        BREACH ``event``, else WARNING; ``alert_failed`` if it cannot be sent."""
        severity = (
            ids.MAV_SEVERITY_CRITICAL
            if event.get("level") in SEVERE_LEVELS
            else ids.MAV_SEVERITY_WARNING
        )
        try:
            await self.vehicle.send_status_text(severity, text)
        except Exception as exc:  # an alert that cannot be sent is logged, never fatal
            self.log.put(new_event("alert_failed", text=text, error=str(exc)))
