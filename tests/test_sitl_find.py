import os
import stat

from alphafence.sitl.find import NOT_FOUND_HELP, find_sitl_binary


def _exe(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def test_precedence(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PATH", str(tmp_path / "bin"))
    monkeypatch.delenv("ARDUPILOT_SITL", raising=False)
    monkeypatch.delenv("ARDUPILOT_HOME", raising=False)
    assert find_sitl_binary() is None
    on_path = _exe(tmp_path / "bin" / "arducopter")
    assert find_sitl_binary() == on_path
    home_build = _exe(tmp_path / "home" / "ardupilot/build/sitl/bin/arducopter")
    assert find_sitl_binary() == home_build
    monkeypatch.setenv("ARDUPILOT_HOME", str(tmp_path / "ap"))
    assert find_sitl_binary() == home_build  # ARDUPILOT_HOME without a build falls through
    tree = _exe(tmp_path / "ap" / "build/sitl/bin/arducopter")
    assert find_sitl_binary() == tree
    explicit = _exe(tmp_path / "custom" / "arducopter")
    monkeypatch.setenv("ARDUPILOT_SITL", str(explicit))
    assert find_sitl_binary() == explicit


def test_help_names_every_place():
    for word in ("ARDUPILOT_SITL", "ARDUPILOT_HOME", "~/ardupilot", "PATH", "BUILD.md"):
        assert word in NOT_FOUND_HELP
    assert os.linesep not in NOT_FOUND_HELP
