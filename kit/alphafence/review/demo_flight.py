"""The demo's flight: ArduPilot SITL flown at a fence with the monitor running.

:func:`fly_at_fence` starts a SITL copter at a home, uploads the compiled onboard fence
(verified by reading it back) and the ``copter-rtl`` fence parameters, starts the monitor
(enforcing, its onboard layer on) on the same MAVSDK connection, takes off in GUIDED and flies
at 10 m/s toward the nearest keep-out fence. The monitor predicts the breach, raises WARNING
and IMMINENT and brakes; the flight ends once the copter has stopped. Everything the monitor
stepped on is kept as a :class:`~alphafence.review.replay.Trace`, every event in order.
SITL is stopped on every way out (error, timeout, Ctrl-C).
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np
import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.errors import SitlError
from alphafence.geo.frame import LocalFrame
from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import WALL, UtcClock
from alphafence.monitor.observe import Observer
from alphafence.monitor.onboard import OnboardLayer
from alphafence.review.replay import Recorder, Trace, speedup_options

ALTITUDE_M = 20.0  # above home
SPEED_MPS = 10.0
CLEAR_M = 30.0  # the goto target keeps this far from every fence
STOPPED_MPS = 0.3
MAX_LEG_M = 3000.0
ARM_TIMEOUT_S = 60.0  # ArduPilot refuses arming until its pre-arm checks pass
FLIGHT_TIMEOUT_S = 90.0  # wall seconds from the first upload to the stop


@dataclass
class Leg:
    """A straight leg from home toward the nearest keep-out fence.

    Attributes
    ----------
    fence : str
        The nearest full-resolution keep-out fence.
    distance_m : float
        How far it is from home.
    target : tuple
        ``(lon, lat)`` of the GUIDED target: on the leg beyond every fence in the way,
        ``CLEAR_M`` from all of them (ArduPilot ignores a target inside an exclusion zone).
    """

    fence: str
    distance_m: float
    target: tuple


def plan_leg(records, items, home) -> Leg:
    """The leg from ``home`` (``(lon, lat)``) toward the nearest keep-out fence of ``records``
    (FenceRecords), clear of them and of the onboard fence ``items`` at its target."""
    frame = LocalFrame(*home)
    keep_out = [r for r in records if r.kind == "keep_out"]
    if not keep_out:
        raise SitlError("no keep-out fence to fly at")
    local = list(frame.geom_to_local(np.array([r.geometry for r in keep_out], dtype=object)))
    onboard = OnboardLayer.from_items(items, frame)
    if onboard.index is not None:
        local += list(onboard.index.local)
    origin = shapely.Point(0.0, 0.0)
    gaps = shapely.distance(origin, np.array(local[: len(keep_out)], dtype=object))
    k = int(np.argmin(gaps))
    nx, ny = shapely.shortest_line(origin, local[k]).coords[1]
    d = math.hypot(nx, ny)
    ux, uy = nx / d, ny / d
    along = d
    while min(shapely.distance(shapely.Point(ux * along, uy * along), local)) < CLEAR_M:
        along += 5.0
        if along > MAX_LEG_M:
            raise SitlError(f"no clear target within {MAX_LEG_M:g} m toward {keep_out[k].site_id}")
    along += 20.0
    lon, lat = frame.to_wgs84(ux * along, uy * along)
    return Leg(keep_out[k].site_id, float(gaps[k]), (float(lon), float(lat)))


class _Milestones(Observer):
    """Events the flight waits on, set from the monitor's observer calls."""

    def __init__(self):
        self.loaded = asyncio.Event()
        self.climbed = asyncio.Event()
        self.acted = asyncio.Event()
        self.stopped = asyncio.Event()
        self.action_t = math.inf

    def on_step(self, step) -> None:
        s = step.sample
        if s.alt_m >= 0.9 * ALTITUDE_M:
            self.climbed.set()
        if s.t > self.action_t + 0.2 and math.hypot(s.vn, s.ve) < STOPPED_MPS:
            self.stopped.set()

    def on_event(self, event) -> None:
        if event["event"] in ("onboard_fence", "onboard_none", "onboard_failed"):
            self.loaded.set()
        if event["event"] == "action" and not self.acted.is_set():
            self.action_t = event["time"]
            self.acted.set()


@dataclass
class Flight:
    """What the demo flight produced.

    Attributes
    ----------
    trace : Trace
        Every sample the monitor stepped on, and the fence the vehicle held.
    events : list of dict
        Every event of the monitor, in order.
    leg : Leg
        Where it flew.
    upload_s : float
        How long the upload and its verification took (wall seconds).
    """

    trace: Trace
    events: list
    leg: Leg
    upload_s: float


async def fly_at_fence(fences_path, items, home, speedup=5.0, say=print, echo=None, binary=None):
    """Fly SITL at the nearest keep-out fence with the enforcing monitor running.

    Parameters
    ----------
    fences_path : str or Path
        The full-resolution fences (a fence GeoJSON), as the monitor reads them.
    items : list of FenceItem
        The compiled onboard fence, uploaded and verified before the flight.
    home : tuple
        ``(lon, lat)`` of SITL's home (the take-off point).
    speedup : float
        SITL's speedup; the monitor's wall-clock durations are scaled for it.
    say : callable
        Called with a line of progress.
    echo : callable, optional
        Called with every monitor event as it happens.
    binary : str or Path, optional
        The SITL binary (found as ``alphafence sitl --find`` finds it if omitted).

    Returns
    -------
    Flight

    Raises
    ------
    SitlError
        SITL did not start, or the flight did not reach its milestones in time.
    VehicleError
        The upload or the parameters were refused.
    """
    from alphafence.fencefiles.fence_geojson import read_fences
    from alphafence.sitl.instance import launch_sitl
    from alphafence.vehicle.fence_transfer import upload_fence
    from alphafence.vehicle.link import open_vehicle
    from alphafence.vehicle.params import PROFILES, apply_params

    records = read_fences(fences_path)
    leg = plan_leg(records, items, home)
    lon, lat = home
    say(f"starting ArduPilot SITL at {lat:.5f},{lon:.5f} (speedup {speedup:g})")
    async with launch_sitl(f"{lat:.7f},{lon:.7f},20,0", speedup=speedup, binary=binary) as sitl:
        async with open_vehicle(sitl.connection_url) as vehicle:
            t0 = time.monotonic()
            report = await upload_fence(vehicle, items)
            upload_s = time.monotonic() - t0
            await apply_params(vehicle, PROFILES["copter-rtl"])
            say(
                f"uploaded {report.items} fence items, read back and verified in {upload_s:.1f} s;"
                " fence parameters copter-rtl set"
            )
            log = EventLog(echo=echo)
            milestones, recorder = _Milestones(), Recorder()
            from alphafence.monitor.runner import Monitor

            monitor = Monitor(
                vehicle,
                FenceSet(records),
                speedup_options(speedup, enforce=True),
                log,
                observers=[milestones, recorder],
            )
            stop = asyncio.Event()
            task = asyncio.create_task(monitor.run(stop))
            try:
                await asyncio.wait_for(_fly(vehicle, sitl, leg, milestones, say), FLIGHT_TIMEOUT_S)
            except asyncio.TimeoutError:
                raise SitlError(f"the demo flight took over {FLIGHT_TIMEOUT_S:g} s") from None
            finally:
                stop.set()
                await asyncio.gather(task, return_exceptions=True)
    recorded = (
        f"a flight recorded from ArduPilot SITL (copter, speedup {speedup:g}, "
        f"{datetime.now(timezone.utc):%Y-%m-%d}): `alphafence demo` at {leg.fence} with the "
        "enforcing monitor"
    )
    trace = Trace(recorded, float(speedup), list(items), list(recorder.samples))
    if trace.samples:  # the samples' monotonic times on this computer's clock
        t0 = trace.samples[0].t
        trace.clock = {"t": t0, "utc": UtcClock.wall().utc(t0), "source": WALL}
    return Flight(trace, list(log.events), leg, upload_s)


async def _fly(vehicle, sitl, leg, milestones, say):
    await milestones.loaded.wait()
    await vehicle.action.set_takeoff_altitude(ALTITUDE_M)
    deadline = time.monotonic() + ARM_TIMEOUT_S
    while True:
        try:
            await vehicle.action.arm()
            break
        except Exception as exc:  # either link's refusal (pre-arm checks)
            if time.monotonic() > deadline:
                raise SitlError(f"arming refused for {ARM_TIMEOUT_S:g} s: {exc}") from None
            await asyncio.sleep(1.0)  # ArduPilot's pre-arm checks: ask again
    await vehicle.action.takeoff()
    say(f"armed, taking off to {ALTITUDE_M:g} m")
    await milestones.climbed.wait()
    lon, lat = leg.target
    await vehicle.action.set_current_speed(SPEED_MPS)
    await vehicle.action.goto_location(lat, lon, sitl.home.alt + ALTITUDE_M, 0.0)
    say(f"flying at {SPEED_MPS:g} m/s toward {leg.fence} ({leg.distance_m:.0f} m away)")
    await milestones.acted.wait()
    await milestones.stopped.wait()
    say("the copter stopped")
