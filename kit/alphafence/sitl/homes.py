"""Where SITL starts: the kit's named homes (``homes.toml``) and its SITL data files.

The data lives in the package, ``kit/alphafence/data/sitl`` (``sitl/`` at the repository root
links to it). A home is a table per name with ``lat``, ``lon``, ``alt`` (metres AMSL), an
optional ``heading`` (degrees) and ``description``::

    [egham]
    lat = 51.43
    lon = -0.55
    alt = 20
    description = "..."

Examples
--------
>>> resolve_home("51.43,-0.55,20").arg()
'51.43,-0.55,20,0'
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from alphafence.errors import InputError
from alphafence.geo.coords import valid_lat, valid_lon

DEFAULT_HOME = "egham"

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def data_path(name: str) -> Path:
    """A file of the kit's SITL data (``homes.toml``, ``alphafence-test.parm``)."""
    return Path(str(resources.files("alphafence").joinpath("data/sitl", name)))


def kit_parm_path() -> Path:
    """The kit's own SITL parameter file."""
    return data_path("alphafence-test.parm")


@dataclass(frozen=True)
class Home:
    """A SITL start position.

    Parameters
    ----------
    name : str
        The name in the homes file (``"custom"`` for one given as numbers).
    lat, lon : float
        Degrees.
    alt : float
        Metres above mean sea level.
    heading : float
        Degrees, 0 (north) to below 360.
    description : str
        What the place is, for ``alphafence sitl --list-homes``.
    """

    name: str
    lat: float
    lon: float
    alt: float
    heading: float = 0.0
    description: str = ""

    def arg(self) -> str:
        """The ``--home`` argument: ``lat,lon,alt,heading``."""
        return ",".join(_num(v) for v in (self.lat, self.lon, self.alt, self.heading))


def _num(value: float) -> str:
    return f"{value:.7f}".rstrip("0").rstrip(".") if value != int(value) else str(int(value))


def _check_home(path, name, lat, lon, alt, heading) -> None:
    for key, value in (("lat", lat), ("lon", lon), ("alt", alt), ("heading", heading)):
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise InputError(path, f"{key} must be a finite number, not {value!r}", name)
    if not valid_lat(lat):
        raise InputError(path, f"lat {lat} is outside -90..90", name)
    if not valid_lon(lon):
        raise InputError(path, f"lon {lon} is outside -180..180", name)
    if not -500 <= alt <= 9000:
        raise InputError(path, f"alt {alt} m is outside -500..9000", name)
    if not 0 <= heading < 360:
        raise InputError(path, f"heading {heading} is outside 0..360", name)


def parse_homes(text: str, path: str | Path = "homes.toml") -> dict[str, Home]:
    """Named homes from TOML text: one table per name with lat, lon, alt, optional heading and
    description. Raises InputError naming the file and the home."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, f"not valid TOML: {exc}") from None
    homes = {}
    for name, table in doc.items():
        if not isinstance(table, dict):
            raise InputError(path, "each home must be a table: [name] with lat, lon, alt", name)
        if not _NAME.match(name):
            raise InputError(path, "names are lower case letters, digits and _", name)
        unknown = set(table) - {"lat", "lon", "alt", "heading", "description"}
        if unknown:
            raise InputError(path, f"unknown keys {sorted(unknown)}", name)
        missing = [k for k in ("lat", "lon", "alt") if k not in table]
        if missing:
            raise InputError(path, f"missing {', '.join(missing)}", name)
        heading = table.get("heading", 0)
        _check_home(path, name, table["lat"], table["lon"], table["alt"], heading)
        homes[name] = Home(
            name,
            float(table["lat"]),
            float(table["lon"]),
            float(table["alt"]),
            float(heading),
            str(table.get("description", "")),
        )
    if not homes:
        raise InputError(path, "no homes defined")
    return homes


def load_homes(path: str | Path | None = None) -> dict[str, Home]:
    """The kit's named homes, or those of another homes file."""
    if path is None:
        path = data_path("homes.toml")
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    return parse_homes(text, path)


def resolve_home(home: str | Home, homes: Mapping[str, Home] | None = None) -> Home:
    """A Home from a name in the homes file, or from ``lat,lon,alt[,heading]``."""
    if isinstance(home, Home):
        return home
    homes = load_homes() if homes is None else homes
    if home in homes:
        return homes[home]
    parts = home.split(",")
    if len(parts) in (3, 4):
        try:
            values = [float(p) for p in parts] + ([0.0] if len(parts) == 3 else [])
        except ValueError:
            values = None
        if values is not None:
            _check_home("home", home, *values)
            return Home("custom", *values)
    known = ", ".join(sorted(homes))
    raise InputError("home", f"unknown home {home!r}: use one of {known}, or lat,lon,alt,heading")
