"""What one position costs the monitor when its code runs back to back, and when it runs once
every 20 ms, as it does at 50 Hz telemetry: the same calls, timed in this thread's CPU time.

Between two positions the process sleeps; whatever else the machine runs in the meantime
(another process, the kernel, on a virtual machine the hypervisor) takes the caches, so each
position's code starts cold. The monitor's share of a core at 50 Hz is set by that cold cost,
not by the loop-timed one: these rows say how far apart the two are on the machine the bench
runs on, per stage of the monitor's path.

    python -m bench --osm … --only monitor
"""

from __future__ import annotations

import statistics
import struct
import time

GAP_S = 0.02  # 50 Hz
REPEAT = 150  # per stage and way

HOME = "malta_airport"  # the SITL home of the monitor's bench on SITL


def cpu_us(fn, gap_s: float, repeat: int = REPEAT) -> float:
    """The median thread CPU time of ``fn()`` in microseconds, each call after ``gap_s`` of
    sleep (0: back to back, after a warm-up)."""
    for _ in range(10):
        fn()
    times = []
    for _ in range(repeat):
        if gap_s:
            time.sleep(gap_s)
        t = time.thread_time_ns()
        fn()
        times.append(time.thread_time_ns() - t)
    return statistics.median(times) / 1e3


def stages(fences):
    """``{name: callable}``: the monitor's per-position stages on SITL's Malta home (decoding
    a GLOBAL_POSITION_INT with pymavlink; the engine's step on it, with ``fences``), after two
    calibrations (a Python function that does nothing; the bare ``struct`` decode of the same
    payload), and the part of the step that costs most cold (pyproj's conversion of the
    position to the fences' metres)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from alphafence.awareness.sample import Sample
    from alphafence.monitor.engine import Engine
    from alphafence.sitl.homes import resolve_home

    home = resolve_home(HOME)
    lat, lon, amsl = home.lat, home.lon, home.alt
    sender = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    lat_e7, lon_e7 = round(lat * 1e7), round(lon * 1e7)
    frame = sender.global_position_int_encode(1000, lat_e7, lon_e7, 80000, 0, 0, 0, 0, 0)
    datagram = bytes(frame.pack(sender))
    receiver = mavlink.MAVLink(None)
    receiver.robust_parsing = True
    engine = Engine(fences)
    clock = [0.0]

    def step():
        clock[0] += GAP_S
        return engine.step(
            Sample(clock[0], lat, lon, 0.0, 0.0, 0.0, "STABILIZE", False, amsl, 0.0, 6)
        )

    fields = struct.Struct("<IiiiihhhH")  # GLOBAL_POSITION_INT's payload, as the wire has it

    def bare():  # the least any decoder does: the payload (MAVLink 2 trims its trailing
        # zeros) padded back and unpacked; no checksum, no object
        return fields.unpack(datagram[10:-2].ljust(fields.size, b"\0"))

    def nothing():  # the least any Python code costs: a call and a return
        return None

    to_local = fences.frame.to_local

    return {
        "a Python function that does nothing (the least any code costs)": nothing,
        "a bare struct decode of its payload (the least any decoder does)": bare,
        "pymavlink decodes one GLOBAL_POSITION_INT": lambda: receiver.parse_buffer(datagram),
        "pyproj converts it to the fences' metres (part of the step)": lambda: to_local(lon, lat),
        "the engine's step on it (SITL's home, Malta's fences)": step,
    }


FAR = (35.82, 14.60)  # 3.7 km off Malta's south-east coast: the lazy check's place


def whole_path(fences, gap_s):
    """``(back to back, once every gap_s)``: the monitor's whole path for one position 3.7 km
    from the nearest fence, from the datagram to the decision: the pymavlink link's framing
    and fast decode, the feed, the runner's check, the engine's lazy check (its full checks
    a few in a thousand). The monitor's own feed task listens, on an event loop of its own."""
    import asyncio

    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from alphafence.monitor.eventlog import EventLog
    from alphafence.monitor.options import MonitorOptions
    from alphafence.monitor.runner import Monitor
    from alphafence.vehicle.pymavlink_link import PymavlinkVehicle

    sender = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    lat_e7, lon_e7 = round(FAR[0] * 1e7), round(FAR[1] * 1e7)
    vehicle = PymavlinkVehicle("udpin:127.0.0.1:14550")  # never opened
    vehicle.target = (1, 1)
    wire = vehicle.link._wire
    monitor = Monitor(vehicle, fences, MonitorOptions(), EventLog(None))
    boot = [0]

    def one():
        boot[0] += 20
        frame = sender.global_position_int_encode(boot[0], lat_e7, lon_e7, 1000, 0, 0, 0, 0, 0)
        data = bytes(frame.pack(sender))
        t = time.thread_time_ns()
        wire.feed(data, ("127.0.0.1", 14550))
        return time.thread_time_ns() - t

    async def measure():
        monitor._loop = asyncio.get_running_loop()
        task = asyncio.create_task(
            monitor._follow("telemetry:position", monitor.feeds["telemetry:position"])
        )
        await asyncio.sleep(0)
        out = []
        for gap in (0.0, gap_s):
            times = []
            for i in range(REPEAT + 10):
                time.sleep(gap or 0.001 * (i < 10))
                times.append(one())
            out.append(statistics.median(times[10:]) / 1e3)
        task.cancel()
        return out

    try:
        return tuple(asyncio.run(measure()))
    finally:
        monitor._loop = None


def run(fences, Row) -> list:
    """One row per stage: back to back against once every 20 ms."""
    fences.index()
    rows = []
    timed = {name: (cpu_us(fn, 0.0), cpu_us(fn, GAP_S)) for name, fn in stages(fences).items()}
    far = "the monitor's whole path, datagram to decision, 3.7 km from the nearest fence"
    timed[far] = whole_path(fences, GAP_S)
    for name, (hot, cold) in timed.items():
        rows.append(
            Row(
                f"cold code: {name}",
                f"{hot:.0f} us back to back, {cold:.0f} us once every 20 ms",
                "-",
                "back to back",
                f"{cold / hot:.1f}x",
                True,
                value=cold,
                unit="us",
                peer_value=hot,
            )
        )
    return rows
