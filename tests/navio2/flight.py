"""The flight of `make navio2-test`: x86 ArduPilot SITL, the armhf monitor, a keep-out fence.

SITL (the kit's harness, ``launch_sitl(radio=True)``) sends MAVLink on two loopback links:
SERIAL0 to this script (the kit's link on x86: upload, parameters, the flight, FENCE_STATUS) and
SERIAL1 to the armhf monitor. The monitor runs in the armhf userland (``--rootfs``) exactly as
the systemd unit starts it: ``docker/alphafence-monitor.service``'s user, ExecStart and
environment (fences, trusted key, event log), with only ``ALPHAFENCE_CONNECT`` (SITL's second
link) and ``ALPHAFENCE_ENFORCE=1`` added; chroot shares the loopback. The fences are signed
here with a fresh key whose public half goes where the unit says.

The flight is tests/test_monitor_flight_sitl.py's at speedup 1: the 100 m exclusion square
150 m north of home uploaded as ArduPilot's own fence (copter-rtl parameters), the same square
as the monitor's keep-out fence, a GUIDED takeoff to 20 m and a goto 400 m north at 10 m/s.
Passes when the monitor's event log holds WARNING, IMMINENT, the brake commanded and done, and
the copter stopped outside the square with no ArduPilot breach. Every wait is on something
arriving (an event-log line, a FENCE_STATUS, a position), bounded by a timeout.

    .venv/bin/python -m tests.navio2.flight --rootfs DIR [--out DIR]   (as root; run.sh does)
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import time
from pathlib import Path

import shapely

from tests.navio2 import rootfs_args
from tests.navio2.readme import UNIT, unit_settings

HOME = "egham"
SPEED = 10.0
TARGET_NORTH = 400.0
STOPPED_MPS = 0.3
MONITOR_READY_S = 240.0  # the armhf monitor's start under qemu: imports, fence download
FLIGHT_S = 120.0
STATUS_AFTER_STOP = 6  # FENCE_STATUS messages (2 Hz) still without a breach after the stop
USERLAND_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


def _ids(rootfs: Path, user: str) -> tuple[int, int]:
    for line in (rootfs / "etc" / "passwd").read_text().splitlines():
        fields = line.split(":")
        if fields[0] == user:
            return int(fields[2]), int(fields[3])
    raise SystemExit(f"navio2 flight: no user {user!r} in the userland (the README creates it)")


def _inside(rootfs: Path, path: str) -> Path:
    return rootfs / path.lstrip("/")


def _fences(frame, square, path: Path) -> None:
    geometry = json.loads(shapely.to_geojson(frame.geom_to_wgs84(square)))
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"site_id": "test/square", "kind": "keep_out", "margin_m": 0.0},
                "geometry": geometry,
            }
        ],
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc) + "\n")


def _prepare(rootfs: Path, frame, square, out: Path) -> tuple[dict, list, tuple]:
    """Fences, key and state directory where the unit expects them; the monitor's argv."""
    from alphafence.fencing.bundle import generate_key, sign

    unit = unit_settings(UNIT.read_text())
    env = dict(unit["Environment"])
    fences = _inside(rootfs, env["ALPHAFENCE_FENCES"])
    _fences(frame, square, fences)
    pub = _inside(rootfs, env["ALPHAFENCE_TRUSTED_KEYS"])
    generate_key(out / "ops.pem", pub)
    sig = sign(fences, out / "ops.pem")
    for path in (fences, sig, pub):  # as the README's `install -m 0644` puts them
        path.chmod(0o644)
    uid, gid = _ids(rootfs, unit["User"])
    log = _inside(rootfs, env["ALPHAFENCE_LOG"])
    log.parent.mkdir(parents=True, exist_ok=True)  # systemd's StateDirectory=
    os.chown(log.parent, uid, gid)
    log.unlink(missing_ok=True)
    return env, [unit["ExecStart"]], (uid, gid, log)


class _Events:
    """The armhf monitor's event log, read as it grows."""

    def __init__(self, path: Path):
        self.path = path
        self.events: list[dict] = []
        self._offset = 0

    def poll(self) -> list[dict]:
        if self.path.is_file():
            with open(self.path, "rb") as f:
                f.seek(self._offset)
                data = f.read()
            end = data.rfind(b"\n") + 1
            self._offset += end
            self.events += [json.loads(line) for line in data[:end].splitlines() if line]
        return self.events

    def first(self, kind, **fields):
        return next(
            (
                e
                for e in self.poll()
                if e["event"] == kind and all(e.get(k) == v for k, v in fields.items())
            ),
            None,
        )


async def _wait(what, predicate, timeout, monitor=None, log=None, poll=0.05):
    deadline = time.monotonic() + timeout
    while not predicate():
        if monitor is not None and monitor.returncode is not None:
            raise RuntimeError(f"{what}: the armhf monitor exited with {monitor.returncode}")
        if time.monotonic() > deadline:
            extra = f" | {log.summary()}" if log is not None else ""
            raise RuntimeError(f"{what}: not within {timeout:g} s{extra}")
        await asyncio.sleep(poll)
    return time.monotonic()


async def fly(rootfs: Path, out: Path) -> dict:
    """The flight; returns what it measured (raises on a failed check)."""
    from alphafence.geo.frame import LocalFrame
    from alphafence.sitl.homes import resolve_home
    from alphafence.sitl.instance import launch_sitl
    from alphafence.vehicle.link import open_vehicle
    from tests.sitl_flight import (
        ALTITUDE,
        NEAR_EDGE,
        FlightLog,
        exclusion_items,
        fence_and_telemetry,
        square_local,
        take_off,
        unwatch,
        watch,
    )

    home = resolve_home(HOME)
    frame = LocalFrame(home.lon, home.lat)
    square = square_local()
    env, argv, (uid, gid, log_path) = _prepare(rootfs, frame, square, out)
    events = _Events(log_path)
    result: dict = {}
    async with launch_sitl(HOME, speedup=1, radio=True) as sitl:
        env |= {"ALPHAFENCE_CONNECT": sitl.radio_url, "ALPHAFENCE_ENFORCE": "1"}
        command = [
            "env", "-i", f"PATH={USERLAND_PATH}", "HOME=/var/lib/alphafence", "LANG=C.UTF-8",
            *(f"{k}={v}" for k, v in env.items()),
            "/usr/sbin/chroot", f"--userspec={uid}:{gid}", "--groups=", str(rootfs), *argv,
        ]  # fmt: skip
        print("armhf monitor:", " ".join(command[command.index("/usr/sbin/chroot") :]), flush=True)
        print("  environment:", " ".join(f"{k}={v}" for k, v in env.items()), flush=True)
        flog = FlightLog(frame)
        async with open_vehicle(sitl.connection_url) as vehicle:
            flog.texts = vehicle.texts
            watchers = watch(flog, vehicle, "positions", "speeds", "modes", "fence")
            monitor = None
            stderr = open(out / "monitor.log", "wb")
            try:
                await fence_and_telemetry(vehicle, flog, exclusion_items(frame))
                t_start = time.monotonic()
                monitor = await asyncio.create_subprocess_exec(
                    *command, stdin=asyncio.subprocess.DEVNULL, stdout=stderr, stderr=stderr
                )
                await _wait(
                    "the armhf monitor's onboard fence (it downloads the vehicle's at start)",
                    lambda: events.first("onboard_fence") or events.first("onboard_failed"),
                    MONITOR_READY_S,
                    monitor,
                )
                ready = events.first("onboard_fence")
                if ready is None:
                    raise RuntimeError(
                        f"onboard fence not loaded: {events.first('onboard_failed')}"
                    )
                result["monitor_ready_s"] = round(time.monotonic() - t_start, 1)
                print(f"armhf monitor ready in {result['monitor_ready_s']} s: {ready}", flush=True)

                await take_off(vehicle.action, flog)
                lon, lat = frame.to_wgs84(0.0, TARGET_NORTH)
                await vehicle.action.set_current_speed(SPEED)
                await vehicle.action.goto_location(float(lat), float(lon), home.alt + ALTITUDE, 0.0)
                t_goto = time.monotonic()
                print(f"flying north at {SPEED:g} m/s toward the square ({NEAR_EDGE:g} m)")
                await _wait(
                    "the monitor's brake",
                    lambda: events.first("action_done", action="brake"),
                    FLIGHT_S,
                    monitor,
                    flog,
                )
                t_action = events.first("action", action="brake")["time"]
                t_stop = await _wait(
                    "the copter stopped",
                    lambda: flog.speeds[-1][0] > t_action + 0.5 and flog.speed() < STOPPED_MPS,
                    30,
                    monitor,
                    flog,
                )
                seen = len(flog.fence)
                await _wait(
                    "FENCE_STATUS after the stop",
                    lambda: len(flog.fence) >= seen + STATUS_AFTER_STOP,
                    30,
                    monitor,
                    flog,
                )
                result["monitor_running_at_end"] = monitor.returncode is None
            finally:
                if monitor is not None and monitor.returncode is None:
                    monitor.send_signal(signal.SIGTERM)
                    try:
                        await asyncio.wait_for(monitor.wait(), 30)
                    except asyncio.TimeoutError:
                        monitor.kill()
                        await monitor.wait()
                stderr.close()
                await unwatch(watchers)
    result["monitor_exit"] = monitor.returncode if monitor else None

    evs = events.poll()
    y = lambda e: float(frame.to_local(e["lon"], e["lat"])[1])  # noqa: E731
    warning = events.first("level", level="WARNING")
    imminent = events.first("level", level="IMMINENT")
    brake = events.first("action", action="brake")
    done = events.first("action_done", action="brake")
    leg = [p for p in flog.positions if p[0] >= t_goto]
    farthest = max(p[2] for p in leg)
    stop = flog.last_position(t_stop)
    inside = [p for p in leg if square.contains(shapely.Point(p[1], p[2]))]
    result |= {
        "events": [e["event"] + ":" + str(e.get("level") or e.get("action") or "") for e in evs],
        "warning": warning and {"t": round(warning["time"] - t_goto, 2), "edge_m": round(NEAR_EDGE - y(warning), 1)},
        "imminent": imminent and {"t": round(imminent["time"] - t_goto, 2), "edge_m": round(NEAR_EDGE - y(imminent), 1)},
        "brake": brake and {"t": round(brake["time"] - t_goto, 2), "done_after_s": done and round(done["time"] - brake["time"], 2)},
        "stopped": {"t": round(t_stop - t_goto, 2), "edge_m": round(NEAR_EDGE - stop[2], 1)},
        "farthest_edge_m": round(NEAR_EDGE - farthest, 1),
        "positions_inside_square": len(inside),
        "ardupilot_breach": flog.first_breach() is not None,
    }  # fmt: skip
    failures = []
    if warning is None or imminent is None:
        failures.append("WARNING and IMMINENT not both logged")
    if brake is None or done is None:
        failures.append("no brake commanded and done")
    if inside or farthest >= NEAR_EDGE:
        failures.append(f"the copter entered the square (farthest {farthest:.1f} m north)")
    if result["ardupilot_breach"]:
        failures.append("ArduPilot reported a fence breach")
    if not result.get("monitor_running_at_end"):
        failures.append("the monitor had stopped before the end of the flight")
    result["failures"] = failures
    return result


def main(argv=None) -> int:
    """Fly; print what was measured as JSON; exit 1 on a failed check."""
    args = rootfs_args("tests.navio2.flight", "navio2-flight", "logs and the key", argv)
    try:
        result = asyncio.run(fly(args.rootfs, args.out))
    except (Exception, BaseException) as exc:  # pytest.fail's Failed is a BaseException
        if isinstance(exc, KeyboardInterrupt):
            raise
        print(f"navio2 flight: FAILED: {exc}", flush=True)
        log = args.out / "monitor.log"
        if log.is_file():
            tail = log.read_text(errors="replace").splitlines()[-15:]
            print("--- armhf monitor output (last lines):", *tail, sep="\n", file=sys.stderr)
        return 1
    print(json.dumps(result, indent=1))
    (args.out / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    w, i, s = result["warning"] or {}, result["imminent"] or {}, result["stopped"]
    said = (
        f"armhf monitor ready in {result['monitor_ready_s']} s; WARNING {w.get('edge_m')} m"
        f" and IMMINENT {i.get('edge_m')} m before the fence, brake, stopped {s['edge_m']} m"
        f" short ({s['t']} s after the goto); ArduPilot breach: {result['ardupilot_breach']}"
    )
    if result["failures"]:
        print("navio2 flight: FAILED: " + "; ".join(result["failures"]) + " | " + said)
        return 1
    print("navio2 flight: passed: " + said)
    return 0


if __name__ == "__main__":
    sys.exit(main())
