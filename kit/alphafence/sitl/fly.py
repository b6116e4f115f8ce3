"""Flying a mission on a simulated vehicle, as a pilot would from a ground station: upload
it, arm, AUTO, and follow it until the vehicle lands and disarms.

For trying the kit end to end on ArduPilot SITL (``alphafence sitl --fly``): the vehicle must
be simulated (it has ArduPilot's ``SIM_SPEEDUP`` parameter), so a real vehicle is never armed
by it.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

from alphafence.errors import VehicleError
from alphafence.geo.coords import to_e7
from alphafence.mavlink import ids

ARM_TIMEOUT_S = 90.0  # pre-arm checks pass once SITL's EKF has settled
ARM_RETRY_S = 1.0
SIM_PARAM = "SIM_SPEEDUP"  # only SITL has the SIM_ parameters


class NotSimulated(VehicleError):
    """The vehicle is real (or does not answer for SIM_SPEEDUP): nothing was sent to it."""


@dataclass
class Flown:
    """What a :func:`fly_mission` flew.

    Attributes
    ----------
    items : int
        Mission items uploaded, home included.
    reached : int
        The last item reached.
    seconds : float
        From the start of the mission to the disarm (wall clock).
    """

    items: int
    reached: int
    seconds: float


def raw_items(rows) -> list:
    """:func:`~alphafence.flights.mission_items.mission_rows` as the vehicle's raw mission
    items (MAVLink's integers for lat, lon), the first after home current."""
    from alphafence.vehicle.values import RawItem

    return [
        RawItem(
            seq=r.seq,
            frame=int(r.frame),
            command=int(r.command),
            current=int(r.seq == 1),
            autocontinue=1,
            param1=float(r.params[0]),
            param2=float(r.params[1]),
            param3=float(r.params[2]),
            param4=float(r.params[3]),
            x=to_e7(r.lat),
            y=to_e7(r.lon),
            z=float(r.alt),
            mission_type=ids.MAV_MISSION_TYPE_MISSION,
        )
        for r in rows
    ]


async def fly_mission(vehicle, rows, say=print, timeout: float = 900.0) -> Flown:
    """Upload the mission ``rows`` to the simulated ``vehicle``, arm, start it and wait until
    the vehicle has landed and disarmed.

    Parameters
    ----------
    vehicle : PymavlinkVehicle
        Connected (:func:`~alphafence.vehicle.link.open_vehicle`).
    rows : list of WplRow
        The mission, home first (:func:`~alphafence.flights.mission_items.mission_rows`).
    say : callable
        Called with a line of progress.
    timeout : float
        Seconds the whole flight may take.

    Returns
    -------
    Flown

    Raises
    ------
    NotSimulated
        The vehicle has no SIM_SPEEDUP parameter.
    VehicleError
        The upload, arming or the flight failed (or took longer than ``timeout``).
    """
    try:
        await vehicle.param.get_param_float(SIM_PARAM)
    except TimeoutError:
        raise NotSimulated(
            f"{vehicle.url}: the vehicle has no {SIM_PARAM} parameter: --fly flies simulated "
            "vehicles (ArduPilot SITL) only; nothing was sent"
        ) from None
    items = raw_items(rows)
    await vehicle.mission_raw.upload_mission(items)
    say(f"mission uploaded: {len(items)} items (home included)")
    armed, reached = _Armed(), [0]
    watchers = [
        asyncio.create_task(armed.follow(vehicle)),
        asyncio.create_task(_progress(vehicle, reached, say)),
    ]
    try:
        await _arm(vehicle, say)
        t0 = time.monotonic()
        await vehicle.mission_raw.start_mission()
        say("AUTO: flying the mission")
        try:
            await asyncio.wait_for(armed.disarmed_after_flight(), timeout)
        except asyncio.TimeoutError:
            raise VehicleError(
                f"the flight took more than {timeout:g} s (last item reached: {reached[0]})"
            ) from None
        seconds = time.monotonic() - t0
    finally:
        for task in watchers:
            task.cancel()
        await asyncio.gather(*watchers, return_exceptions=True)
    say(f"landed and disarmed after {seconds:.0f} s")
    return Flown(len(items), reached[0], seconds)


async def _arm(vehicle, say) -> None:
    """Arm, asking again while pre-arm checks fail (SITL's EKF settling)."""
    deadline = time.monotonic() + ARM_TIMEOUT_S
    while True:
        try:
            await vehicle.action.arm()
            say("armed")
            return
        except VehicleError as exc:
            if time.monotonic() > deadline:
                raise VehicleError(f"could not arm within {ARM_TIMEOUT_S:g} s: {exc}") from None
        await asyncio.sleep(ARM_RETRY_S)  # a retry interval, not a wait for an outcome


class _Armed:
    """The vehicle's armed state from its HEARTBEATs: an event once armed, then disarmed."""

    def __init__(self):
        self.was_armed = False
        self.done = asyncio.Event()

    async def follow(self, vehicle) -> None:
        async for armed in vehicle.telemetry.subscribe_armed():
            if armed:
                self.was_armed = True
            elif self.was_armed:
                self.done.set()

    async def disarmed_after_flight(self) -> None:
        await self.done.wait()


async def _progress(vehicle, reached, say) -> None:
    async for p in vehicle.mission_raw.subscribe_mission_progress():
        last = p.total - 1  # home is item 0
        if reached[0] < p.current <= last:
            reached[0] = p.current
            say(f"item {p.current} of {last}")
