"""``make demo`` on a fresh clone says what it installs before pip runs quietly."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_make_demo_says_what_it_installs_before_pip_runs():
    # -n: print the recipe without running it; -W: as if pyproject.toml had changed (a fresh
    # clone has no .venv, so the install runs)
    out = subprocess.run(
        ["make", "-n", "-W", "pyproject.toml", "demo"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.splitlines()
    pips = [k for k, line in enumerate(out) if "pip install" in line]
    says = [k for k, line in enumerate(out) if line.startswith("echo") and "installing" in line]
    assert pips and says and says[0] < pips[0], out
    assert "first run only" in out[says[0]]
    assert all("--quiet" in out[k] for k in pips)  # pip's own output stays quiet
