"""The SITL command line: the argument vector, its defaults files and a parameter file.

MAVLink goes to loopback only: SERIAL0 is ``udpclient:127.0.0.1:PORT`` (SITL sends to a UDP
port that *we* listen on), and SERIAL1/SERIAL2, which SITL would otherwise open as TCP
listeners on all interfaces, are ``none`` (or SERIAL1 a second loopback link, like a
telemetry radio).

Examples
--------
>>> from alphafence.sitl.homes import Home
>>> sitl_command("arducopter", Home("here", 51.43, -0.55, 20), port=14550)[:5]
['arducopter', '--model', '+', '--home', '51.43,-0.55,20,0']
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

from alphafence.errors import SitlError
from alphafence.sitl.find import COPTER_DEFAULTS, ardupilot_tree
from alphafence.sitl.homes import Home, kit_parm_path
from alphafence.sitl.ports import LOOPBACK, MAX_INSTANCE

MODEL = "+"  # a plus-frame quad; the kit's parameter file sets FRAME_CLASS 1, FRAME_TYPE 0

_PARAM = re.compile(r"^[A-Z][A-Z0-9_]{0,15}$")


def copter_defaults(binary: Path) -> Path | None:
    """ArduPilot's copter defaults from the tree ``binary`` was built in, if there is one."""
    tree = ardupilot_tree(Path(binary))
    return tree / COPTER_DEFAULTS if tree is not None else None


def defaults_files(binary: Path, extra: Iterable[str | Path] = ()) -> list[Path]:
    """SITL's ``--defaults`` list, in load order (later files win): ArduPilot's copter.parm
    (when the tree is found), the kit's own test file, then ``extra``."""
    files = []
    tree_defaults = copter_defaults(binary)
    if tree_defaults is not None:
        files.append(tree_defaults)
    files.append(kit_parm_path())
    files.extend(Path(p) for p in extra)
    return files


def sitl_command(
    binary: str | Path,
    home: Home,
    *,
    port: int,
    instance: int = 0,
    speedup: float = 1,
    defaults: Iterable[str | Path] = (),
    model: str = MODEL,
    radio_port: int | None = None,
    serial1: str | None = None,
) -> list[str]:
    """The SITL argument vector: MAVLink on SERIAL0 to ``udpin`` on loopback ``port``; SERIAL1
    and SERIAL2 (TCP listeners by default) switched off, or SERIAL1 to loopback ``radio_port``
    (a second MAVLink link, like a telemetry radio: ArduPilot's channel 1), or to ``serial1``
    as SITL writes a device (``uart:/dev/pts/3:57600``: a serial port)."""
    if serial1 is not None and radio_port is not None:
        raise SitlError("SERIAL1 is either the radio link or a serial device, not both")
    if serial1 is None:
        serial1 = "none" if radio_port is None else f"udpclient:{LOOPBACK}:{radio_port}"
    defaults = [str(p) for p in defaults]
    for path in defaults:
        if "," in path:
            raise SitlError(f"SITL takes a comma-separated defaults list; rename {path}")
    if not 0 <= instance <= MAX_INSTANCE:
        raise SitlError(f"instance {instance} is outside 0..{MAX_INSTANCE}")
    if not speedup > 0:
        raise SitlError(f"speedup must be positive, not {speedup}")
    argv = [
        str(binary),
        "--model", model,
        "--home", home.arg(),
        "--speedup", f"{speedup:g}",
        "-I", str(instance),
    ]  # fmt: skip
    if defaults:
        argv += ["--defaults", ",".join(defaults)]
    argv += [
        "--serial0", f"udpclient:{LOOPBACK}:{port}",
        "--serial1", serial1,
        "--serial2", "none",
    ]  # fmt: skip
    return argv


def write_param_file(path: Path, values: Mapping[str, float]) -> Path:
    """A parameter file of ``NAME VALUE`` lines."""
    lines = ["# parameters set by the caller of the AlphaFence SITL launcher"]
    for name, value in values.items():
        if not _PARAM.match(name):
            raise SitlError(f"not an ArduPilot parameter name: {name!r}")
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise SitlError(f"parameter {name} must be a finite number, not {value!r}")
        lines.append(f"{name} {value!r}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
