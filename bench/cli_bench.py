"""Issue 13 target: the command line starts fast. ``alphafence --help`` builds the parser of
every verb, which imports no geometry (numpy, shapely, pyproj), scipy, matplotlib, pyosmium or
vehicle link (tests/test_imports.py checks that); the wall time of a whole process is timed
here, the median of 15 runs, against the bare interpreter's start as the peer."""

from __future__ import annotations

import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

RUNS = 15
TARGET_S = 0.3


def _command():
    """The installed console script beside this interpreter, else ``python -m alphafence``."""
    script = Path(sys.executable).with_name("alphafence")
    if script.exists():
        return [str(script)]
    found = shutil.which("alphafence")
    return [found] if found else [sys.executable, "-m", "alphafence"]


def _wall(argv, runs=RUNS):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def run(Row):
    """``alphafence --help`` and ``alphafence monitor --help``: median wall seconds."""
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
            )
        )
    return rows
