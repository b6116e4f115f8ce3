"""Issue 13 target: the command line starts fast. ``alphafence --help`` builds the parser of
every verb, which imports no geometry (numpy, shapely, pyproj), scipy, matplotlib, pyosmium or
vehicle link (tests/test_imports.py checks that); the wall time of a whole process is timed
here, the median of 15 runs, against the bare interpreter's start as the peer.

Issue 23 target: ``alphafence build`` of Malta as a whole process (imports included, the
default ``--jobs``) at least 1.5x faster than its named peer, ``bench/peer_build.py``
(pyosmium and the ``alphashape`` package at a fixed radius, one process); the median of 7
runs of each, taken in turns so that a load on the machine weighs on both alike, with the
``--jobs 1`` build beside them. Their bytecode is cached, as an installed package's is."""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = 15
TARGET_S = 0.3
BUILD_RUNS = 7
BUILD_TARGET = 1.5  # times faster than the peer
PEER_RADIUS_M = 60.0


def _command():
    """The installed console script beside this interpreter, else ``python -m alphafence``."""
    script = Path(sys.executable).with_name("alphafence")
    if script.exists():
        return [str(script)]
    found = shutil.which("alphafence")
    return [found] if found else [sys.executable, "-m", "alphafence"]


def _wall(argv, runs=RUNS, env=None):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(
            argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=env
        )
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def peer_tags(rules):
    """``{key: [values] or None}``: the tags that make an area restricted under ``rules``,
    for :mod:`bench.peer_build` (which imports nothing of AlphaFence)."""
    tags = {}
    for rule in rules.rules:
        if "area" in rule.geometry:
            for key, values in rule.tags:
                if values is None or tags.get(key, ()) is None:
                    tags[key] = None
                else:
                    tags[key] = sorted({*tags.get(key, ()), *values})
    return tags


def build_rows(osm, Row):
    """``alphafence build`` of ``osm`` (default --jobs, and --jobs 1) against the peer."""
    from alphafence.zones.rules import load_rules

    peer_script = Path(__file__).with_name("peer_build.py")
    with tempfile.TemporaryDirectory(prefix="alphafence-cli-bench-") as tmp:
        tags = Path(tmp, "tags.json")
        tags.write_text(json.dumps(peer_tags(load_rules())))
        ours = _command() + ["build", osm, "-o", str(Path(tmp, "fences.geojson")), "-q"]
        peer = [sys.executable, str(peer_script), osm, str(Path(tmp, "peer.geojson"))]
        peer += [str(tags), str(PEER_RADIUS_M)]
        # bytecode cached as an installed package has it (pip compiles it; an editable
        # install writes it on the first run), even where PYTHONDONTWRITEBYTECODE is set:
        # in a folder of its own, written by an untimed first run of each command
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = str(Path(tmp, "pycache"))
        commands = {"auto": ours, "one": ours + ["--jobs", "1"], "peer": peer}
        times = {k: [] for k in commands}
        for argv in commands.values():
            _wall(argv, 1, env)
        for _ in range(BUILD_RUNS):
            for k, argv in commands.items():
                times[k].append(_wall(argv, 1, env))
    auto, one, p = (statistics.median(times[k]) for k in ("auto", "one", "peer"))
    name = Path(osm).name
    return [
        Row(
            f"cli: alphafence build {name} (whole process, default --jobs, median of {BUILD_RUNS})",
            f"{auto:.2f} s",
            f">= {BUILD_TARGET:g}x faster",
            f"osmium + alphashape at {PEER_RADIUS_M:g} m {p:.2f} s",
            f"{p / auto:.2f}x",
            p / auto >= BUILD_TARGET,
            value=auto,
            unit="s",
            peer_value=p,
        ),
        Row(
            f"cli: alphafence build {name} --jobs 1 (whole process, median of {BUILD_RUNS})",
            f"{one:.2f} s",
            "-",
            f"osmium + alphashape at {PEER_RADIUS_M:g} m {p:.2f} s",
            f"{p / one:.2f}x",
            True,
            value=one,
            unit="s",
            peer_value=p,
        ),
    ]


def run(Row, osm=None):
    """``alphafence --help`` and ``alphafence monitor --help``: median wall seconds; with
    ``osm``, the whole build of it against the peer (:func:`build_rows`)."""
    bare = _wall([sys.executable, "-c", "pass"])
    rows = []
    for args in (["--help"], ["monitor", "--help"]):
        s = _wall(_command() + args)
        rows.append(
            Row(
                f"cli: alphafence {' '.join(args)} (whole process, median of {RUNS})",
                f"{s:.3f} s",
                f"< {TARGET_S} s",
                f"python -c pass {bare:.3f} s",
                f"{s / bare:.1f}x",
                s < TARGET_S,
                value=s,
                unit="s",
                peer_value=bare,
            )
        )
    if osm is not None:
        rows += build_rows(osm, Row)
    return rows
