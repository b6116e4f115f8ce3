"""The README's Navio2 install steps, the systemd unit and the armv7 image agree.

`make navio2-test` runs the README's ``navio2-install`` blocks in a Debian armhf userland and
starts the monitor as ``docker/alphafence-monitor.service`` does; these checks keep the three
(README, unit, Dockerfile.armv7) naming the same venv, user, entrypoint and files, so that what
the armhf test proves is what a Navio2 user types and what systemd runs.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tests.navio2.readme import README, UNIT, install_blocks, unit_settings

ROOT = Path(__file__).resolve().parents[1]
SUITES = ("trixie", "bookworm")


def _commands(block: str) -> list[list[str]]:
    """The block's commands as argument lists (continuations joined, comments dropped)."""
    text = block.replace("\\\n", " ")
    return [shlex.split(line, comments=True) for line in text.splitlines() if line.strip()]


def _readme():
    return README.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def unit():
    return unit_settings(UNIT.read_text(encoding="utf-8"))


def _after(cmd, program):
    """The arguments after ``program`` in ``cmd`` (``sudo`` and the like before it)."""
    return cmd[cmd.index(program) + 1 :] if program in cmd else None


@pytest.mark.parametrize("suite", SUITES)
def test_each_suite_creates_the_units_venv_user_and_entrypoint(suite, unit):
    commands = [c for b in install_blocks(_readme(), suite) for c in _commands(b)]
    assert commands, f"no navio2-install block for {suite}"
    venv = str(Path(unit["ExecStart"]).parent.parent)  # /opt/alphafence from .../bin/...
    assert unit["Environment"]["PATH"].split(":")[0] == f"{venv}/bin"

    venvs = [_after(c, "python3") for c in commands if _after(c, "python3")]
    assert ["-m", "venv", "--system-site-packages", venv] in venvs

    pips = [c for c in commands if f"{venv}/bin/pip" in c]
    kit = [c[-1] for c in pips if c[-1].startswith("$HOME/alphafence[")]
    assert kit and all("companion" in k for k in kit), pips
    assert not any("mavsdk" in arg or "vehicle" in arg for c in pips for arg in c), pips

    installs = [_after(c, "install") for c in commands if c[:2] == ["sudo", "install"]]
    assert ["-m", "0755", "~/alphafence/docker/entrypoint.sh", unit["ExecStart"]] in installs

    users = [_after(c, "useradd") for c in commands if "useradd" in c]
    assert len(users) == 1
    user = users[0]
    assert user[-1] == unit["User"] and "--system" in user
    home = user[user.index("--home-dir") + 1]
    assert home == f"/var/lib/{unit['StateDirectory']}"
    assert Path(unit["Environment"]["ALPHAFENCE_LOG"]).parent == Path(home)

    apt = [arg for c in commands if _after(c, "apt") and "install" in c for arg in c]
    assert {"python3-venv", "python3-numpy", "python3-pyproj", "proj-bin"} <= set(apt)


def test_the_service_block_puts_files_where_the_unit_reads_them(unit):
    # the service block has a marker of its own: systemd does not run in the armhf userland
    m = re.search(r"<!-- navio2-service -->\n```sh\n(.*?)```", _readme(), re.S)
    assert m, "README: no navio2-service block"
    commands = _commands(m.group(1))
    copied = next(c for c in commands if "fences.geojson" in c)
    dest = copied[-1]
    env = unit["Environment"]
    for name in ("ALPHAFENCE_FENCES", "ALPHAFENCE_TRUSTED_KEYS"):
        assert str(Path(dest) / Path(env[name]).name) == env[name]
        assert Path(env[name]).name in copied
    assert f"{Path(env['ALPHAFENCE_FENCES']).name}.sig.json" in copied
    unit_copy = next(c for c in commands if "docker/alphafence-monitor.service" in " ".join(c))
    assert unit_copy[-1] == "/etc/systemd/system/"
    assert ["sudo", "systemctl", "enable", "--now", UNIT.stem] in commands


def test_the_unit_runs_the_entrypoint_as_its_user(unit):
    assert unit["User"] == "alphafence" and unit["Restart"] == "always"
    assert unit["ExecStart"] == "/opt/alphafence/bin/alphafence-entrypoint"
    assert unit["Environment"]["ALPHAFENCE_CONNECT"] == "udpin://127.0.0.1:14551"
    assert "-D udp:127.0.0.1:14551" in _readme()


def test_the_armv7_image_installs_what_the_trixie_steps_install():
    text = (ROOT / "docker" / "Dockerfile.armv7").read_text()
    assert text.count("FROM debian:trixie-slim") == 1
    readme_apt = {
        arg
        for c in _commands(install_blocks(_readme(), "trixie")[0])
        if "apt" in c and "install" in c
        for arg in c
        if not arg.startswith("-") and arg not in ("sudo", "apt", "install")
    }
    m = re.search(r"apt-get install -y --no-install-recommends(.*?)&&", text, re.S)
    image_apt = set(m.group(1).replace("\\", " ").split())
    assert image_apt == readme_apt
    assert "python3 -m venv --system-site-packages /opt/alphafence" in text
    assert "[companion]" in text and "mavsdk" not in text
    assert "USER alphafence" in text and 'ENTRYPOINT ["alphafence-entrypoint"]' in text


def test_install_blocks_are_found_in_order_and_a_bare_marker_is_an_error():
    text = (
        "<!-- navio2-install: trixie bookworm -->\n```sh\necho one\n```\n"
        "<!-- navio2-install: bookworm -->\n\n```sh\necho two\n```\n"
        "<!-- navio2-install: trixie -->\nno block\n"
    )
    assert install_blocks(text, "bookworm") == ["echo one\n", "echo two\n"]
    with pytest.raises(ValueError, match="marker without a code block"):
        install_blocks(text, "trixie")
    assert install_blocks(text, "buster") == []


def test_the_armv7_image_steps_become_the_script_navio2_test_runs():
    from tests.navio2.dockerfile import script

    text = (ROOT / "docker" / "Dockerfile.armv7").read_text()
    lines = script(text, "debian:trixie-slim").splitlines()
    assert lines[0] == "set -euxo pipefail"
    assert "cp -r /context/pyproject.toml /context/README.md /context/LICENSE /src/" in lines
    assert "cp -r /context/docker/entrypoint.sh /opt/alphafence/bin/alphafence-entrypoint" in lines
    runs = [i for i, line in enumerate(lines) if line.startswith("apt-get update")]
    pip = [i for i, line in enumerate(lines) if "/opt/alphafence/bin/pip install" in line]
    assert len(runs) == 1 and len(pip) == 1 and runs[0] < pip[0]
    assert (
        lines[-1].startswith("setpriv --reuid=alphafence") and "alphafence-entrypoint" in lines[-1]
    )
    with pytest.raises(ValueError, match="stands for debian:bookworm-slim"):
        script(text, "debian:bookworm-slim")
    with pytest.raises(ValueError, match="HEALTHCHECK: not understood"):
        script("FROM x\nHEALTHCHECK CMD true\n", "x")
