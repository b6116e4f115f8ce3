"""The bench phase of `make navio2-test`: the monitor's CPU per position on the armhf userland
(emulated by qemu-user) beside the same measurement on this x86 machine.

One x86 SITL (speedup 1) streams to a loopback port. :mod:`bench.monitor_probe` runs the real
monitor (pymavlink link, the Navio2's) on that port over the Malta fences at 10 and 50 Hz, first
on x86 (the checkout's venv), then in the armhf userland (its ``/opt/alphafence`` install, the
bench code from the copied checkout), each followed by the floor (an endpoint doing nothing with
the same datagrams). Figures are CPU time of the process, so under qemu-user they include the
translation: they say how the armv7 build of the kit's dependencies behaves (a missing wheel,
a pure-Python fallback shows as a jump in the ratio), not how fast a Pi is.

Passes when every measurement checked about as many positions as asked for, the armhf install
uses every compiled piece x86 uses, and the emulated CPU per position is within
:data:`MAX_EMULATED_RATIO` of x86's.

    .venv/bin/python -m tests.navio2.bench --rootfs DIR [--out DIR]   (as root; run.sh does)
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from pathlib import Path

from tests.navio2 import rootfs_args

ROOT = Path(__file__).resolve().parents[2]
MALTA = ROOT.parent / "shared" / "data" / "osm" / "malta-2018-08-27.osm.pbf"
RATES = "10,50"
MAX_EMULATED_RATIO = 40.0  # armhf under qemu-user against x86, CPU per position
MIN_RATE = 0.8  # of the rate asked for: fewer checks means the monitor fell behind
USERLAND_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
PROBE_TIMEOUT_S = 900.0  # qemu's start: imports, the fences' index


async def _probe(argv, env=None) -> list[dict]:
    proc = await asyncio.create_subprocess_exec(
        *argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
    )
    out, err = await asyncio.wait_for(proc.communicate(), PROBE_TIMEOUT_S)
    if proc.returncode != 0:
        tail = err.decode(errors="replace").strip().splitlines()[-20:]
        raise RuntimeError(f"probe {argv[0]} exited {proc.returncode}:\n" + "\n".join(tail))
    return [json.loads(line) for line in out.decode().splitlines() if line.startswith("{")]


async def measure(rootfs: Path, fences: Path) -> dict:
    """``{"x86": rows, "armhf": rows}`` from one SITL."""
    from alphafence.sitl.instance import launch_sitl

    inside = "/root/bench-fences.geojson"
    (rootfs / inside.lstrip("/")).write_bytes(fences.read_bytes())
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        url = sitl.pymavlink_url
        args = ["--connect", url, "--hz", RATES, "--floor"]
        host = [sys.executable, "-m", "bench.monitor_probe", "--fences", str(fences), *args]
        x86 = await _probe(host)
        guest = (
            "cd /root/alphafence && exec /opt/alphafence/bin/python -m bench.monitor_probe "
            + " ".join([f"--fences {inside}", *args])
        )
        env = {"PATH": USERLAND_PATH, "HOME": "/root", "LANG": "C.UTF-8"}
        armhf = await _probe(["chroot", str(rootfs), "sh", "-c", guest], env=env)
    return {"x86": x86, "armhf": armhf}


def verdict(got: dict) -> tuple[list[dict], list[str]]:
    """The rows to report (the schema of ``bench-out/results.json``) and what failed."""
    rows, failed = [], []
    x86 = {(r["link"], r["hz"]): r for r in got["x86"]}
    missing = [
        k
        for k, v in got["armhf"][0]["native"].items()
        if v is False and got["x86"][0]["native"].get(k)
    ]
    if missing:
        failed.append(f"the armhf install lacks {', '.join(missing)} (x86 has it)")
    for r in got["armhf"]:
        here = x86.get((r["link"], r["hz"]))
        if r["link"] == "floor":
            name = f"floor: a UDP endpoint doing nothing, {r['hz']:g} Hz streams"
        else:
            name = f"monitor CPU per position, {r['link']} link, {r['hz']:g} Hz, Malta fences"
            for where, row in (("x86", here), ("armhf", r)):
                if row is not None and row["rate"] < MIN_RATE * row["hz"]:
                    failed.append(f"{where} {row['hz']:g} Hz: {row['rate']:.1f} checks/s")
        per = "per_position_s" in r
        value = 1e6 * r["per_position_s"] if per else 100 * r["share"]
        peer = (
            None if here is None else (1e6 * here["per_position_s"] if per else 100 * here["share"])
        )
        ratio = None if not peer else value / peer
        ok = not per or ratio is None or ratio <= MAX_EMULATED_RATIO
        if not ok:
            failed.append(f"{name}: {ratio:.1f}x x86's (more than {MAX_EMULATED_RATIO:g}x)")
        unit = "us/position" if per else "% of a core"
        rows.append(
            {
                "group": "navio2",
                "name": f"{name}, armhf under qemu-user (emulated)",
                "result": (
                    f"{value:.0f} {unit}, {100 * r['share']:.2f} % of a core"
                    if per
                    else f"{value:.2f} {unit}, {r['rate']:.0f} datagrams/s"
                ),
                "value": value,
                "unit": unit,
                "target": f"<= {MAX_EMULATED_RATIO:g}x x86's" if per else "-",
                "peer": None if peer is None else f"x86 {peer:.{0 if per else 2}f} {unit}",
                "peer_value": peer,
                "ratio": None if ratio is None else f"{ratio:.1f}x",
                "ok": ok,
            }
        )
    return rows, failed


def build_fences(out: Path) -> Path:
    """Malta's fences, built by the x86 kit."""
    fences = out / "malta-fences.geojson"
    if not MALTA.is_file():
        raise SystemExit(f"navio2 bench: no {MALTA} (the OSM extracts beside the checkout)")
    cli = [sys.executable, "-m", "alphafence", "build", str(MALTA), "-o", str(fences)]
    subprocess.run(cli, check=True, stdout=subprocess.DEVNULL)
    return fences


def main(argv=None) -> int:
    if os.geteuid() != 0:
        raise SystemExit("navio2 bench: run as root (chroot)")
    args = rootfs_args("python -m tests.navio2.bench", "navio2-bench", "results folder", argv)
    got = asyncio.run(measure(args.rootfs, build_fences(args.out)))
    rows, failed = verdict(got)
    (args.out / "results.json").write_text(json.dumps({"raw": got, "rows": rows}, indent=1) + "\n")
    for r in rows:
        peer = f"   (x86: {r['peer'][4:]}, {r['ratio']})" if r["peer"] else ""
        print(f"  {r['name']}: {r['result']}{peer}{'' if r['ok'] else '   NOT OK'}")
    summary = "; ".join(failed) if failed else "armhf figures within bounds of x86's"
    print(f"navio2 bench: {'FAILED: ' if failed else ''}{summary}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
