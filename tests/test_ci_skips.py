"""Under ``CI=true`` a test whose real part is missing (SITL here) fails instead of skipping;
without it, the user gets the one-line skip. Run on this suite's own SITL test with every
SITL hidden (no $ARDUPILOT_*, a HOME without ~/ardupilot, no ../shared SITL, a PATH of the
system's folders only)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST = "tests/test_upload_sitl.py::test_fence_parameters_applied"


def run_hidden(tmp_path, ci):
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARDUPILOT_")}
    env.update(HOME=str(tmp_path), PATH="/usr/bin:/bin", ALPHAFENCE_SHARED_SITL=str(tmp_path))
    env["CI"] = "true" if ci else ""
    argv = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", TEST, "-k", "pymavlink"]
    return subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


def test_a_hidden_sitl_fails_under_ci_and_skips_otherwise(tmp_path):
    failed = run_hidden(tmp_path, ci=True)
    assert failed.returncode != 0, failed.stdout[-2000:]
    assert "CI=true and a real part is missing" in failed.stdout
    skipped = run_hidden(tmp_path, ci=False)
    assert skipped.returncode == 0, skipped.stdout[-2000:]
    assert "1 skipped" in skipped.stdout and "no ArduPilot SITL binary found" in skipped.stdout
