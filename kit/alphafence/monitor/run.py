"""Running the monitor on a vehicle: connect, run a :class:`~alphafence.monitor.runner.Monitor`
until told to stop, record the flight's telemetry log if asked, close the event log."""

from __future__ import annotations

import asyncio

from alphafence.monitor.eventlog import EventLog
from alphafence.monitor.events import UtcClock
from alphafence.monitor.runner import Monitor


async def run_monitor(
    url,
    fences,
    options,
    log_path=None,
    stop: asyncio.Event | None = None,
    echo=None,
    timeout: float = 10.0,
    signing_key: bytes | None = None,
    link: str | None = None,
    tlog_path=None,
    observers=(),
    live=None,
):
    """Connect to the vehicle at ``url`` and run a :class:`Monitor` until ``stop`` is set.

    Parameters
    ----------
    url : str
        The vehicle's connection URL.
    fences : FenceSet
        Every fence.
    options : MonitorOptions
        What to predict, decide and command.
    log_path : str or Path, optional
        Append every event to this JSON-lines file.
    stop : asyncio.Event, optional
        Ends the monitor when set (never, if omitted).
    echo : callable, optional
        Called with every event (the CLI prints them).
    timeout : float
        Seconds to find the vehicle.
    signing_key : bytes, optional
        MAVLink 2 signing key for the link.
    link : str, optional
        The vehicle link (:func:`~alphafence.vehicle.link.choose_link`).
    tlog_path : str or Path, optional
        Record every frame the vehicle sends to this ``.tlog`` (the pymavlink link).
    observers : sequence of Observer
        Watch the monitor (:mod:`alphafence.monitor.observe`).
    live : LiveOptions, optional
        Zones from a live source, in flight (:mod:`alphafence.monitor.live`).

    Returns
    -------
    Monitor
        The monitor, stopped (``monitor.engine.checks``, ``monitor.log.events``).

    Raises
    ------
    LinkError
        When no vehicle answers within ``timeout``.
    """
    from alphafence.monitor.tlog import record_link
    from alphafence.vehicle.link import open_vehicle

    stop = stop or asyncio.Event()
    log = EventLog(log_path, echo, clock=UtcClock.wall())
    try:
        async with open_vehicle(url, timeout, signing_key, link) as vehicle:
            monitor = Monitor(vehicle, fences, options, log, observers=observers, live=live)
            tlog = await record_link(vehicle, tlog_path) if tlog_path else None
            try:
                await monitor.run(stop)
            finally:
                if tlog is not None:
                    await tlog.close()
            return monitor
    finally:
        await log.close()
