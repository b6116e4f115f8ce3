"""Where the vehicle is and where its home is, read before a fence is compiled for it.

A compiled fence must leave home (and the vehicle's position) clear
(:mod:`alphafence.onboard.clear`), so ``upload`` and the rolling fence read them first:
HOME_POSITION, asked for with MAV_CMD_REQUEST_MESSAGE (ArduPilot and PX4 answer it; ArduPilot
acknowledges the request and sends nothing while it has no home), and GLOBAL_POSITION_INT, which
both stream. A vehicle without a GPS fix has neither: the fence is then compiled without them,
and the caller says so.
"""

from __future__ import annotations

import asyncio
import contextlib

from alphafence.mavlink import ids

ASK_EVERY_S = 0.5  # HOME_POSITION is asked for this often until it comes
HOME_WAIT_S = 4.0  # a watch's first answer is waited for this long
HOME_EVERY_S = 10.0  # then home is asked for again this often (it moves where the vehicle arms)


async def _first(vehicle, name, sysid, read):
    async for m in vehicle.messages(name):
        if m.system_id == sysid:
            got = read(m.fields)
            if got is not None:
                return got
    return None


def _lonlat(fields, lon="longitude", lat="latitude"):
    try:
        x, y = int(fields[lon]), int(fields[lat])
    except (KeyError, TypeError, ValueError):
        return None
    if x == 0 and y == 0:  # no fix: the autopilot's zeros, not a place
        return None
    return x / 1e7, y / 1e7


async def read_home(vehicle, timeout: float = 3.0):
    """The vehicle's home ``(lon, lat)`` (degrees), or None when none comes within
    ``timeout`` seconds (no home yet: no GPS fix).

    Parameters
    ----------
    vehicle : Vehicle
    timeout : float

    Returns
    -------
    tuple or None
    """
    sysid = await vehicle.system_id()

    async def ask():
        while True:
            vehicle.send_command_long(ids.MAV_CMD_REQUEST_MESSAGE, ids.MAVLINK_MSG_ID_HOME_POSITION)
            await asyncio.sleep(ASK_EVERY_S)

    asker = asyncio.ensure_future(ask())
    try:
        return await asyncio.wait_for(_first(vehicle, "HOME_POSITION", sysid, _lonlat), timeout)
    except asyncio.TimeoutError:
        return None
    finally:
        asker.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await asker


async def read_position(vehicle, timeout: float = 3.0):
    """The vehicle's position ``(lon, lat)`` from GLOBAL_POSITION_INT, or None when none with
    a fix comes within ``timeout`` seconds."""
    sysid = await vehicle.system_id()
    with contextlib.suppress(asyncio.TimeoutError):
        found = _first(vehicle, "GLOBAL_POSITION_INT", sysid, lambda f: _lonlat(f, "lon", "lat"))
        return await asyncio.wait_for(found, timeout)
    return None


async def whereabouts(vehicle, fallback_home=None, clearance_m: float = 0.0):
    """The vehicle's home and position (``(lon, lat)``, each None when it has none; a home
    it has not got yet is ``fallback_home``), and a line that says them and what the fence
    leaves them (``clearance_m``).

    Returns
    -------
    tuple
        ``(home, position, line, warning)``: ``warning`` when the vehicle has no home.
    """
    home, position = await asyncio.gather(read_home(vehicle), read_position(vehicle))
    if home is not None:
        at = f", vehicle at {position[1]:.7f},{position[0]:.7f}" if position else ""
        line = (
            f"home {home[1]:.7f},{home[0]:.7f}{at}: the fence leaves them {clearance_m:g} m clear"
        )
        return home, position, line, False
    line = "the vehicle has no home yet (no GPS fix?): the fence is compiled " + (
        f"for --home, and leaves it {clearance_m:g} m clear" if fallback_home is not None
        else "without it and may cover where it arms (give --home)")  # fmt: skip
    return fallback_home, position, line, True


class HomeWatch:
    """The vehicle's home, kept current in flight (the rolling fence compiles round it).

    The first :meth:`current` starts a task that asks for home every :data:`HOME_EVERY_S`
    and waits up to :data:`HOME_WAIT_S` for its first answer; later calls return at once.

    Parameters
    ----------
    vehicle : Vehicle
    """

    def __init__(self, vehicle):
        self.vehicle = vehicle
        self.home = None  # (lon, lat), the last one read
        self._task = None
        self._read = asyncio.Event()

    async def current(self):
        """Home ``(lon, lat)``, or None while the vehicle has none."""
        if self._task is None:
            self._task = asyncio.create_task(self._watch(), name="vehicle:home")
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(self._read.wait()), HOME_WAIT_S)
        return self.home

    async def _watch(self):
        while True:
            try:
                self.home = await read_home(self.vehicle) or self.home
            except asyncio.CancelledError:
                raise
            except Exception:  # noqa: BLE001 - a link that cannot say: the last home read
                pass
            self._read.set()
            await asyncio.sleep(HOME_EVERY_S)

    def close(self) -> None:
        """Stop asking."""
        if self._task is not None:
            self._task.cancel()
