"""The 133,000-area build against the commit before the as-read work (b1ba46e), in the same run.

That commit's ``kit/`` is taken from git (``git archive``) into ``$ALPHAFENCE_CACHE/bench`` once
and run with this checkout's environment (``PYTHONPATH`` first: its modules, these
dependencies). The two builds of ``bench/synth_db``'s 133,000 keep-out areas (GeoJSON lines,
``--jobs 2``, pinned to 2 cores) alternate, ``RUNS`` times each, so the machine's slow minutes
fall on both; the ratio is of the medians. Target: within 1.05x.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import tarfile
import tempfile
from pathlib import Path

from bench.scale_bench import measure
from bench.synth_db import cache_dir, cached_database

BASELINE = "b1ba46e"
AREAS = 133_000
RUNS = 3
TARGET = 1.05
ROOT = Path(__file__).resolve().parents[1]


def baseline_kit() -> Path | None:
    """The baseline commit's ``kit`` folder (unpacked once), or None without git or it."""
    out = cache_dir() / f"kit-{BASELINE}"
    if (out / "kit" / "alphafence" / "__init__.py").is_file():
        return out / "kit"
    with tempfile.TemporaryDirectory() as tmp:
        tar = Path(tmp) / "kit.tar"
        try:
            subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(tar), BASELINE, "kit"],
                           check=True, capture_output=True)  # fmt: skip
        except (OSError, subprocess.CalledProcessError):
            return None
        with tarfile.open(tar) as t:
            try:
                t.extractall(out, filter="data")
            except TypeError:  # Python before 3.11.4: git's own archive, trusted
                t.extractall(out)  # noqa: S202
    return out / "kit"


def run(extract, Row, console):
    """One row: the medians' ratio."""
    kit = baseline_kit()
    if kit is None:
        return [Row(f"build 133,000 areas against {BASELINE}", f"not run: no git history of "
                    f"{BASELINE} here", f"<= {TARGET}x", "-", "-", False)]  # fmt: skip
    db, _ = cached_database(extract, AREAS, "lines")
    python = str(Path(os.environ.get("VIRTUAL_ENV", "")) / "bin" / "python")
    if not os.path.exists(python):
        import sys

        python = sys.executable
    walls = {"now": [], BASELINE: []}
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "fences.geojson")
        for k in range(RUNS):
            for which in ("now", BASELINE):
                env = {**os.environ}
                if which == BASELINE:
                    env["PYTHONPATH"] = str(kit)
                argv = [python, "-m", "alphafence", "build", str(db), "-o", out, "--jobs", "2",
                        "-q"]  # fmt: skip
                m = _measure_env(argv, env)
                walls[which].append(m["wall"])
                console.print(f"  {which}: run {k + 1}, {m['wall']:.1f} s")
    now, then = statistics.median(walls["now"]), statistics.median(walls[BASELINE])
    ratio = now / then
    runs = ", ".join(f"{a:.1f}/{b:.1f}" for a, b in zip(walls["now"], walls[BASELINE]))
    return [Row(f"build 133,000 areas (--jobs 2) against {BASELINE} (medians of {RUNS}, "
                f"alternating: {runs} s)", f"{now:.1f} s", f"<= {TARGET}x",
                f"{BASELINE} {then:.1f} s", f"{ratio:.2f}x", ratio <= TARGET, now, "s", then)]  # fmt: skip


def _measure_env(argv, env):
    old = dict(os.environ)
    os.environ.clear()
    os.environ.update(env)
    try:
        return measure(argv, 600, 8e9)
    finally:
        os.environ.clear()
        os.environ.update(old)
