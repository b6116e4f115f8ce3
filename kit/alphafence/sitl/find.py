"""Find a user-built ArduPilot copter SITL binary. AlphaFence ships no ArduPilot code."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

COPTER_DEFAULTS = "Tools/autotest/default_params/copter.parm"  # inside an ArduPilot tree
NOT_FOUND_HELP = (
    "no ArduPilot SITL binary found: set ARDUPILOT_SITL=/path/to/arducopter, or ARDUPILOT_HOME to an "
    "ArduPilot tree built with './waf configure --board sitl && ./waf copter' (see ArduPilot's BUILD.md), "
    "or build it at ~/ardupilot, or put arducopter on PATH"
)


def candidates():
    """Where to look, in order: $ARDUPILOT_SITL, $ARDUPILOT_HOME's build, ~/ardupilot's build,
    ``arducopter`` on PATH (paths that may not exist)."""
    env = os.environ.get("ARDUPILOT_SITL")
    if env:
        yield Path(env).expanduser()
    home = os.environ.get("ARDUPILOT_HOME")
    if home:
        yield Path(home).expanduser() / "build/sitl/bin/arducopter"
    yield Path.home() / "ardupilot/build/sitl/bin/arducopter"
    onpath = shutil.which("arducopter")
    if onpath:
        yield Path(onpath)


def find_sitl_binary() -> Path | None:
    """The first executable of: $ARDUPILOT_SITL, $ARDUPILOT_HOME/build/sitl/bin/arducopter,
    ~/ardupilot/build/sitl/bin/arducopter, arducopter on PATH."""
    for path in candidates():
        if path.is_file() and os.access(path, os.X_OK):
            return path
    return None


def ardupilot_tree(binary: Path) -> Path | None:
    """The ArduPilot source tree a binary was built in (for its default parameter files)."""
    for parent in binary.resolve().parents:
        if (parent / COPTER_DEFAULTS).is_file():
            return parent
    return None
