"""Argument types and option groups shared by the verbs.

Every value is checked where argparse converts it, by the ``type=`` functions below, so a
verb's ``run()`` receives values already parsed and in range:

* :func:`bbox` (``MINLON,MINLAT,MAXLON,MAXLAT``) fails as a usage error (argparse's message
  and exit status 2);
* :func:`latlon` (``LAT,LON``) and the number types raise :class:`~alphafence.errors.InputError`
  naming the option, which :func:`alphafence.cli.main` prints on one line (exit status 2).

:class:`Parser` also takes a value that starts with a minus sign and reads as numbers
(``--bbox -77.5,38.7,-77.0,39.0``, ``--from -35.36,149.16``) as a value, not as an option.

Building the parser imports no geometry (numpy, shapely, pyproj): ``alphafence --help`` starts
in a fraction of a second. A verb imports the library in its ``run()``, and the argument types
import what they need when they are called.
"""

from __future__ import annotations

import argparse
import math
import re

from alphafence.cli.common import DefaultsFormatter
from alphafence.errors import InputError

_NUMBER = r"(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
# "-5", "-.5", "-1e3", and comma lists "-77.5,38.7,-77.0,39.0" (argparse alone knows only the first two)
NEGATIVE_VALUE = re.compile(rf"^-{_NUMBER}(?:,-?{_NUMBER})*$")


class Parser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` that reads ``-77.5,38.7`` as a value.

    argparse takes an argument that starts with ``-`` for an option unless it looks like a
    negative number (``-5``, ``-.5``), so ``--bbox -77.5,38.7,-77.0,39.0`` would fail with
    "expected one argument". This parser also accepts comma-separated lists of numbers that
    start with a negative one; the sub-parsers of its verbs are of the same class. Its help
    shows every option's default (:class:`DefaultsFormatter`).

    Examples
    --------
    >>> p = Parser(prog="x")
    >>> _ = p.add_argument("--bbox")
    >>> p.parse_args(["--bbox", "-77.5,38.7,-77.0,39.0"]).bbox
    '-77.5,38.7,-77.0,39.0'
    """

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", DefaultsFormatter)  # every option's default shown
        super().__init__(*args, **kwargs)
        # argparse consults this when an argument starts with '-' and names no option
        self._negative_number_matcher = NEGATIVE_VALUE


# ---------------------------------------------------------------------------------------------
# argument types


def bbox(text: str) -> tuple:
    """argparse type: ``MINLON,MINLAT,MAXLON,MAXLAT`` -> a (minlon, minlat, maxlon, maxlat) tuple.

    A malformed box, coordinates out of range or a min not below its max is a usage error
    (``argparse.ArgumentTypeError``).
    """
    from alphafence.zones.features import parse_bbox

    try:
        return parse_bbox(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(exc.message) from None


def latlon(flag: str):
    """argparse type for the option ``flag``: ``LAT,LON`` -> a ``(lon, lat)`` tuple.

    Parameters
    ----------
    flag : str
        The option, named in the error (``"--from"``).

    Returns
    -------
    callable
        The type function; it raises :class:`~alphafence.errors.InputError` (exit status 2)
        on a malformed or out-of-range position.

    Examples
    --------
    >>> latlon("--from")("-35.36,149.16")
    (149.16, -35.36)
    """

    def parse(text):
        from alphafence.geo.coords import valid_lonlat

        try:
            lat, lon = (float(v) for v in text.split(","))
        except ValueError:
            raise InputError(flag, f"expected LAT,LON, got {text!r}") from None
        if not valid_lonlat(lon, lat):
            raise InputError(flag, f"coordinate (lat {lat}, lon {lon}) out of range")
        return lon, lat

    return parse


def _number(flag, convert, ok, wrong):
    def parse(text):
        value = convert(text)  # ValueError: argparse's "invalid float value: 'x'"
        if not ok(value):
            raise InputError(flag, f"must be {wrong}, not {value}")
        return value

    parse.__name__ = convert.__name__
    return parse


def _of(unit):
    return f" of {unit}" if unit else ""


def positive(flag: str, unit: str = ""):
    """argparse type for ``flag``: a finite number > 0 (float).

    Parameters
    ----------
    flag : str
        The option, named in the error.
    unit : str, optional
        What the number counts (``"metres"``), for the error.

    Examples
    --------
    >>> positive("--alt", "metres")("30")
    30.0
    """
    return _number(
        flag, float, lambda v: math.isfinite(v) and v > 0, f"a positive number{_of(unit)}"
    )


def non_negative(flag: str, unit: str = ""):
    """argparse type for ``flag``: a finite number >= 0 (float); see :func:`positive`."""
    return _number(
        flag, float, lambda v: math.isfinite(v) and v >= 0, f"a non-negative number{_of(unit)}"
    )


def at_least(flag: str, minimum: int):
    """argparse type for ``flag``: an integer >= ``minimum``.

    Examples
    --------
    >>> at_least("--items", 1)("40")
    40
    """
    return _number(flag, int, lambda v: v >= minimum, f"at least {minimum}")


def connection(text: str) -> str:
    """argparse type of ``--connect``: the connection as given, once
    :func:`~alphafence.vehicle.endpoints.parse_endpoint` reads it (else an InputError naming
    it and the accepted forms)."""
    from alphafence.vehicle.endpoints import EndpointError, parse_endpoint

    try:
        parse_endpoint(text)
    except EndpointError as exc:
        raise InputError(f"--connect {text.strip()!r}", exc.message) from None
    return text.strip()


def add_connect_option(p: argparse.ArgumentParser, required: bool = True) -> None:
    """Add ``--connect`` (every connection form, checked as it is parsed) to ``p``."""
    from alphafence.vehicle.endpoints import HELP

    help = f"{HELP}. Example: --connect /dev/ttyACM0"
    p.add_argument("--connect", required=required, type=connection, metavar="CONN", help=help)


# ---------------------------------------------------------------------------------------------
# option groups


def figure_wants(figure):
    """What drawing ``figure`` (a path, or None for no figure) needs: matplotlib."""
    return [("matplotlib", f"drawing {figure}")] if figure else []


def add_compile_options(p: argparse.ArgumentParser) -> None:
    """Add the options of ``compile`` and ``upload`` that size and place the onboard fence.

    The operating area (``--area`` or ``--bbox``) is each verb's own; :func:`compile_from_args`
    reads both.
    """
    from alphafence.onboard import HOME_CLEARANCE_M as CLEARANCE_M

    add_storage_options(p)
    p.add_argument(
        "--items",
        type=at_least("--items", 1),
        metavar="N",
        help="at most N items (within the profile)",
    )
    p.add_argument(
        "--distance",
        type=non_negative("--distance", "metres"),
        default=2000.0,
        metavar="M",
        help="fences within M metres of the mission's flight path or of the box (default 2000)",
    )
    p.add_argument(
        "--keep-in", type=float, metavar="M", help="add an inclusion fence M metres around the area"
    )
    p.add_argument(
        "--return-point",
        type=latlon("--return-point"),
        metavar="LAT,LON",
        help="the fence return point",
    )
    p.add_argument(
        "--home",
        type=latlon("--home"),
        metavar="LAT,LON",
        help="the vehicle's home: no compiled item covers it or comes within --home-clearance "
        "(default: a mission's home with --area; upload reads the vehicle's own)",
    )
    p.add_argument(
        "--home-clearance",
        type=non_negative("--home-clearance", "metres"),
        default=CLEARANCE_M,
        metavar="M",
        help=f"metres between home (and the vehicle) and any compiled keep-out item or keep-in "
        f"edge, where the fences themselves leave that much (default {CLEARANCE_M:g})",
    )


def compile_from_args(args, records, home=None, position=None):
    """Compile ``records`` for where the vehicle flies and the storage that
    :func:`add_compile_options` and the verb's ``--area`` / ``--bbox`` describe: the fences
    within ``--distance`` of the mission's flight path (its legs in order, the way back
    included), or of the box.

    ``home`` (the vehicle's, else ``--home``, else the mission's) and ``position`` (the
    vehicle's, ``(lon, lat)``) are left clear (:mod:`alphafence.onboard.clear`).

    Returns
    -------
    alphafence.onboard.compile.CompileResult

    Raises
    ------
    InputError
        A fence that holds home (named), ``--return-point`` or ``--bbox`` typed the wrong way round (lon,lat for a position,
        lat,lon for a box: the swap is suggested), or no fence near the area (the plan would
        leave the vehicle without a fence).
    """
    import shapely

    from alphafence.onboard.clear import KeepClear
    from alphafence.onboard.compile import compile_fences
    from alphafence.onboard.corridor import flight_path_from_plan
    from alphafence.onboard.rules import require_fence
    from alphafence.zones.mistakes import check_box, check_point

    if getattr(args, "area", None):
        area, where = flight_path_from_plan(args.area), f"the flight path of {args.area}"
    else:
        area = shapely.box(*args.bbox)
        where = "the box " + ",".join(f"{v:g}" for v in args.bbox)
    geoms = [r.geometry for r in records if r.kind in ("keep_out", "keep_in")]
    home = home or getattr(args, "home", None)
    if home is None and getattr(args, "area", None):  # the mission's home: its first position
        home = tuple(shapely.get_coordinates(area)[0])
    elif getattr(args, "home", None) is not None:
        check_point("--home", args.home, [area, *geoms], args.fences)
    keep = KeepClear.of(home, position, args.home_clearance)
    if args.return_point is not None:  # LAT,LON typed the wrong way round
        check_point("--return-point", args.return_point, [area, *geoms], args.fences)
    result = compile_fences(
        records,
        area,
        storage_profile(args),
        args.distance,
        args.keep_in,
        args.return_point,
        args.items,
        keep,
        getattr(args, "inclusions", None),
    )
    if not getattr(args, "area", None):  # a box that selects nothing, typed lat,lon
        check_box("--bbox", args.bbox, geoms, args.fences, reach_m=args.distance)
    require_fence(result, args.fences, where)  # no empty plan, for compile as for upload
    return result


def add_storage_options(p: argparse.ArgumentParser) -> None:
    """Add ``--autopilot``, ``--profile`` and ``--sd-fence-kb`` to ``p``."""
    from alphafence.mavlink.autopilots import AUTOPILOTS
    from alphafence.mavlink.storage import PROFILES

    p.add_argument(
        "--autopilot",
        choices=AUTOPILOTS,
        help="whose fence rules to compile for (default: the vehicle's own, from its "
        "HEARTBEAT; without a vehicle, ardupilot)",
    )
    p.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="vehicle fence storage (default copter for ArduPilot: 70 items, 560 bytes; px4 "
        "for PX4: 64 items; navio2: ArduPilot's fence in a file of --sd-fence-kb, full "
        "resolution)",
    )
    p.add_argument(
        "--sd-fence-kb",
        type=sd_fence_kb,
        metavar="N",
        help="with --profile navio2: the vehicle's BRD_SD_FENCE, 1-64 kB (default 64)",
    )


def sd_fence_kb(text: str) -> int:
    """argparse type of ``--sd-fence-kb``: an integer from 1 to 64 (kB of ``BRD_SD_FENCE``).

    Examples
    --------
    >>> sd_fence_kb("32")
    32
    """
    from alphafence.mavlink.storage import SD_FENCE_MAX_KB

    value = int(text)  # ValueError: argparse's "invalid int value: 'x'"
    if not 1 <= value <= SD_FENCE_MAX_KB:
        raise InputError("--sd-fence-kb", f"must be 1 to {SD_FENCE_MAX_KB} (kB), not {value}")
    return value


def autopilot_of_args(args) -> str:
    """The autopilot the work is for: ``--autopilot``, else the ``--profile``'s, else
    ArduPilot."""
    from alphafence.mavlink.storage import PROFILES

    if getattr(args, "autopilot", None):
        return args.autopilot
    if getattr(args, "profile", None):
        return PROFILES[args.profile].autopilot
    return "ardupilot"


def storage_profile(args):
    """The :class:`~alphafence.mavlink.storage.Profile` that ``--autopilot``, ``--profile``
    (and, for ``navio2``, ``--sd-fence-kb``) name: without ``--profile``, the autopilot's
    default (copter for ArduPilot, px4 for PX4).

    Raises
    ------
    InputError
        ``--sd-fence-kb`` with another profile, or a profile of another autopilot.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> storage_profile(SimpleNamespace(profile="navio2", sd_fence_kb=8)).items
    1024
    >>> storage_profile(SimpleNamespace(profile=None, autopilot="px4")).items
    64
    """
    from alphafence.mavlink.storage import (
        DEFAULT_PROFILE,
        PROFILES,
        navio2_profile,
        vehicle_profile,
    )

    autopilot = autopilot_of_args(args)
    name = getattr(args, "profile", None) or DEFAULT_PROFILE[autopilot]
    kb = getattr(args, "sd_fence_kb", None)
    if name == "navio2":
        profile = navio2_profile(kb) if kb is not None else PROFILES["navio2"]
    elif kb is not None:
        raise InputError("--sd-fence-kb", "sizes the navio2 profile only: add --profile navio2")
    else:
        profile = PROFILES[name]
    return vehicle_profile(profile, autopilot, "the fence is for")
