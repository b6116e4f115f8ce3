"""Issue 12: which vehicle link for the Navio2, by measurement. The CPU of a bare position
stream (GLOBAL_POSITION_INT at 10 and 50 Hz from SITL, each position delivered to Python) on
each link: the kit's pymavlink link (pure Python, any platform), MAVSDK 4's native binding
(x86-64/arm64 wheels only) and mavsdk-grpc 4 (the gRPC API with its own ``mavsdk_server``
process: the MAVSDK that has armv7 wheels). CPU is this process's (all threads) plus
``mavsdk_server``'s for mavsdk-grpc, the least of three windows.

mavsdk-grpc is not a dependency of the kit: ``make bench`` installs it; without it its rows
say how to get it.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import os
import time

from alphafence.sitl.find import find_sitl_binary

RATES = (10.0, 50.0)
SETTLE_S = 3.0
SECONDS = 6.0
WINDOWS = 3


def _children_cpu(name: str) -> float:
    """CPU seconds of this process's children whose command line contains ``name``."""
    total = 0.0
    me = str(os.getpid())
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmd = fh.read()
        except OSError:
            continue
        if fields[1] == me and name.encode() in cmd:
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


async def _windows(count, extra_cpu=lambda: 0.0):
    await asyncio.sleep(SETTLE_S)
    best = None
    for _ in range(WINDOWS):
        c0, e0, n0, w0 = time.process_time(), extra_cpu(), count(), time.perf_counter()
        await asyncio.sleep(SECONDS)
        wall = time.perf_counter() - w0
        cpu = time.process_time() - c0 + extra_cpu() - e0
        got = (cpu / wall, (count() - n0) / wall, cpu / max(1, count() - n0))
        if best is None or got[0] < best[0]:
            best = got
    return best


async def _kit_link(url, link, hz):
    from alphafence.vehicle.link import open_vehicle

    async with open_vehicle(url, link=link) as vehicle:
        await vehicle.telemetry.set_rate_position(hz)
        n = [0]
        stream = getattr(vehicle.telemetry, "subscribe_position_velocity", None)
        stream = stream or vehicle.telemetry.subscribe_position

        async def count():
            async for _ in stream():
                n[0] += 1

        task = asyncio.create_task(count())
        try:
            return await _windows(lambda: n[0])
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


async def _grpc(url, hz):
    from mavsdk_grpc import System

    drone = System()
    await drone.connect(system_address=url)
    try:
        async for state in drone.core.connection_state():
            if state.is_connected:
                break
        await drone.telemetry.set_rate_position(hz)
        n = [0]

        async def count():
            async for _ in drone.telemetry.position():
                n[0] += 1

        task = asyncio.create_task(count())
        try:
            return await _windows(lambda: n[0], lambda: _children_cpu("mavsdk_server"))
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
    finally:
        with contextlib.suppress(Exception):
            drone._stop_mavsdk_server()
        await asyncio.sleep(0.5)  # its UDP port free again


FLOOR_SENDER = """
import socket, sys, time
port, hz = int(sys.argv[1]), float(sys.argv[2])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
t = time.monotonic()
while True:
    s.sendto(bytes(40), ("127.0.0.1", port))
    t += 1 / hz
    time.sleep(max(0.0, t - time.monotonic()))
"""


async def _floor(hz):
    """The CPU of an asyncio UDP endpoint that does nothing with datagrams arriving at ``hz``:
    what waking up costs on this machine now (a loaded machine's caches make it dearer)."""
    import subprocess
    import sys

    n = [0]

    class Count(asyncio.DatagramProtocol):
        def datagram_received(self, data, addr):
            n[0] += 1

    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_datagram_endpoint(Count, local_addr=("127.0.0.1", 0))
    port = transport.get_extra_info("sockname")[1]
    sender = subprocess.Popen([sys.executable, "-c", FLOOR_SENDER, str(port), str(hz)])
    try:
        return await _windows(lambda: n[0])
    finally:
        sender.kill()
        sender.wait()
        transport.close()


async def _measure(links):
    from alphafence.sitl import launch_sitl

    out = {("floor", hz): await _floor(hz) for hz in RATES}
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        for link in links:
            for hz in RATES:
                if link == "mavsdk-grpc":
                    out[link, hz] = await _grpc(sitl.connection_url, hz)
                else:
                    out[link, hz] = await _kit_link(sitl.connection_url, link, hz)
    return out


def run(Row):
    from alphafence.vehicle.link import NoLinkError, choose_link

    if find_sitl_binary() is None:
        return [Row("position stream CPU per link", "skipped: no SITL binary", "-", "-", "-", True)]
    links, missing = [], []
    for link in ("pymavlink", "mavsdk"):
        try:
            links.append(choose_link(link))
        except NoLinkError:
            missing.append(link)
    if importlib.util.find_spec("mavsdk_grpc") is not None:
        links.append("mavsdk-grpc")
    else:
        missing.append("mavsdk-grpc")
    got = asyncio.run(_measure(links))
    rows = []
    for hz in RATES:
        share, _, per = got["floor", hz]
        rows.append(
            Row(
                f"floor: an asyncio UDP endpoint doing nothing, {hz:g} datagrams/s",
                f"{100 * share:.2f} % of a core, {1e6 * per:.0f} us/datagram",
                "-", "-", "-", True,
            )
        )  # fmt: skip
        ours = got.get(("pymavlink", hz))
        for link in links:
            share, rate, per = got[link, hz]
            rows.append(
                Row(
                    f"position stream on SITL, {hz:g} Hz, {link} link",
                    f"{100 * share:.2f} % of a core, {1e6 * per:.0f} us/position, {rate:.0f}/s",
                    "the lowest: the Navio2's link" if link == "pymavlink" else "-",
                    "-"
                    if link == "pymavlink" or ours is None
                    else f"pymavlink {100 * ours[0]:.2f} %",
                    "-" if link == "pymavlink" or ours is None else f"{share / ours[0]:.2f}x",
                    link != "pymavlink" or all(share <= got[k, hz][0] for k in links),
                )
            )
        for link in missing:
            rows.append(
                Row(
                    f"position stream on SITL, {hz:g} Hz, {link} link",
                    f"not installed (pip install {link})",
                    "-", "-", "-", True,
                )
            )  # fmt: skip
    return rows
