"""The companion image's entrypoint, run as a script with a stand-in `alphafence`."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENTRY = ROOT / "docker" / "entrypoint.sh"


@pytest.fixture
def env(tmp_path):
    fake = tmp_path / "bin" / "alphafence"
    fake.parent.mkdir()
    fake.write_text('#!/bin/sh\nprintf "%s\\n" "$@"\n')
    fake.chmod(0o755)
    fences = tmp_path / "fences.geojson"
    fences.write_text("{}")
    return {
        "PATH": f"{fake.parent}:/usr/bin:/bin",
        "ALPHAFENCE_CONNECT": "udpin://0.0.0.0:14550",
        "ALPHAFENCE_FENCES": str(fences),
    }


def run(env, *args):
    return subprocess.run(
        ["sh", str(ENTRY), *args], env=env, capture_output=True, text=True, timeout=10
    )


def test_builds_the_monitor_command(env):
    env |= {
        "ALPHAFENCE_ENFORCE": "1",
        "ALPHAFENCE_HORIZON": "12",
        "ALPHAFENCE_LOG": "/tmp/e.jsonl",
        "ALPHAFENCE_BREACH_ACTION": "land",
        "ALPHAFENCE_IMMINENT_ACTION": "reroute",
        "ALPHAFENCE_ONBOARD": "off",
    }
    res = run(env, "--decel", "3")
    assert res.returncode == 0, res.stderr
    assert res.stdout.split("\n")[:-1] == [
        "monitor",
        "--connect",
        "udpin://0.0.0.0:14550",
        "--fences",
        env["ALPHAFENCE_FENCES"],
        "--decel",
        "3",
        "--enforce",
        "--horizon",
        "12",
        "--breach-action",
        "land",
        "--imminent-action",
        "reroute",
        "--onboard",
        "off",
        "--log",
        "/tmp/e.jsonl",
    ]


def test_alert_only_by_default_and_unsigned_only_on_request(env):
    out = run(env).stdout.split("\n")
    assert "--enforce" not in out and "--allow-unsigned" not in out
    assert "--allow-unsigned" in run(env | {"ALPHAFENCE_ALLOW_UNSIGNED": "yes"}).stdout.split("\n")


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"ALPHAFENCE_CONNECT": ""}, "set ALPHAFENCE_CONNECT"),
        ({"ALPHAFENCE_FENCES": "/nonexistent/f.geojson"}, "cannot read ALPHAFENCE_FENCES"),
        ({"ALPHAFENCE_ENFORCE": "maybe"}, "ALPHAFENCE_ENFORCE must be 1 or 0"),
    ],
)
def test_bad_configuration_is_one_clear_line(env, change, expected):
    res = run(env | change)
    assert res.returncode == 64 and expected in res.stderr and res.stderr.count("\n") == 1


def test_dockerfile_runs_as_non_root_and_uses_the_entrypoint():
    text = (ROOT / "docker" / "Dockerfile").read_text()
    assert "USER alphafence" in text and 'ENTRYPOINT ["alphafence-entrypoint"]' in text
    assert "python:3.11-slim" in text and os.access(ENTRY, os.X_OK)
