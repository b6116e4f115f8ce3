"""OpenAir airspace files (WinPilot's format, extended by Naviter; the gliding and ultralight
community's airspace files).

An airspace starts at ``AC class``; ``AN`` names it, ``AY`` types it, ``AL``/``AH`` give its
floor and ceiling (``SFC``/``GND``, ``UNL``, ``FL65``, ``1500ft AGL``, ``2900AMSL FT``...;
feet when no unit; :mod:`alphafence.zones.openair_alt`). Its outline: ``DP`` points,
``DA radius, start, end`` and ``DB point, point`` arcs about the centre ``V X=`` in the
direction ``V D=+`` (clockwise, the default, reset at each ``AC``) or ``-``, ``DC radius``
circles; distances in nautical miles, coordinates in degrees, minutes and seconds
(``52:13:05 N 001:35:03 W``) or decimal minutes. Arcs and circles are drawn outward
(:mod:`alphafence.zones.openair_shape`), so the polygon never cuts into the airspace.

A limit without a numeric meaning (``NOTAM``, ``BCTA FT``) widens the band, with a note: a
floor to the ground, a ceiling to unlimited. Every fault of a file is found before any is
raised, so one message lists them all; a build may leave out the airspaces at fault instead
(``invalid``), naming each.
"""

from __future__ import annotations

import math
import re

import shapely

from alphafence.errors import InputError, InputErrors
from alphafence.zones.airspace import features_from_volumes
from alphafence.zones.jsonfile import max_json_bytes, read_limited
from alphafence.zones.openair_alt import Unreadable, read_altitude
from alphafence.zones.openair_shape import (
    arc_from_angles,
    arc_from_points,
    outline_polygon,
    parse_coordinates,
)

NM = 1852.0
SUFFIXES = (".openair",)
_LIMITS = {
    "AL": ("floor", (0.0, "AGL"), "the ground"),
    "AH": ("ceiling", (None, "AMSL"), "unlimited"),
}


def looks_like_openair(text: str) -> bool:
    """Whether text starts (after comments and blank lines) with an ``AC`` record.

    Examples
    --------
    >>> looks_like_openair("* UK airspace\\n\\nAC R\\nAN EGR101\\n")
    True
    >>> looks_like_openair("QGC WPL 110\\n")
    False
    """
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("*"):
            return bool(re.match(r"AC(\s|$)", line, re.IGNORECASE))
    return False


def sniff(path) -> bool:
    """Whether a file's first 64 kB look like OpenAir (see :func:`looks_like_openair`)."""
    try:
        with open(path, "rb") as fh:
            return looks_like_openair(fh.read(65536).decode("latin-1"))
    except OSError:
        return False


class _Airspace:
    """One airspace as its records are read."""

    def __init__(self, n, line, cls):
        self.n, self.line, self.cls = n, line, cls
        self.name = self.type = None
        self.lower = (0.0, "AGL")
        self.upper = (None, "AMSL")
        self.parts = []  # ("P", lon, lat) or ("A", centre, r0, b0, r1, b1, cw, sweep, start, end)
        self.circle = None
        self.centre = None
        self.cw = True
        self.airway = False
        self.faults = []  # (line, message) per record that could not be read
        self.unread = {}  # "AL"/"AH" -> (line, text, why): limits without a numeric meaning

    def label(self, line=None):
        """``airspace 3 (EGR101 TEST), line 27``: the airspace and a line of it."""
        name = self.name or f"AC {self.cls}"
        return f"airspace {self.n} ({name}), line {self.line if line is None else line}"


def _volume(path, space, skipped):
    """The airspace's volume, or None for an airway left out; InputError when it is no area."""
    if space.airway:
        if skipped is None:
            raise InputError(path, "airway segments (DY) are not read", space.label())
        skipped["OpenAir airway (DY) segments, not read"] += 1
        return None
    if not space.parts and space.circle is None:
        raise InputError(path, "an airspace without DP, DA, DB or DC records", space.label())
    geom, props = outline_polygon(path, space.label(), space.circle, space.parts)
    if not shapely.make_valid(geom).area > 0:
        raise InputError(path, "its points lie on one line: not an area", space.label())
    (lower, lref), (upper, uref) = space.lower, space.upper
    if lower is not None and upper is not None and lref == uref and upper <= lower:
        raise InputError(path, f"AH {upper:g} m is not above AL {lower:g} m", space.label())
    tags = {"airspace:format": "openair", "airspace:class": space.cls}
    if space.type:
        tags["airspace:type"] = space.type
    if space.name:
        tags["name"] = space.name
    props.update(lower_reference=lref, upper_reference=uref, airspace_class=space.cls)
    return geom, tags, f"openair/{space.n}", lower, upper, props


def widened_notes(path, space) -> list:
    """Notes on an airspace's limits that had no numeric meaning and were widened, one line
    each naming the file, the airspace and the line."""
    notes = []
    for cmd, (line, text, why) in sorted(space.unread.items(), key=lambda kv: kv[1]):
        limit, _, wide = _LIMITS[cmd]
        notes.append(
            f"{path}: {space.label(line)}: {cmd} {text!r} is not read ({why}): "
            f"the {limit} is taken as {wide}"
        )
    return notes


def _text(path):
    data = read_limited(path, max_json_bytes(), "larger than ALPHAFENCE_MAX_JSON_MB")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:  # older files are Latin-1 (Naviter asks for UTF-8 now)
        return data.decode("latin-1")


def _numbers(path, where, text, count):
    fields = [f for f in re.split(r"[,\s]+", text.split("*")[0].strip()) if f]
    try:
        values = [float(f) for f in fields]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(path, f"expected {count} number(s), got {text.strip()!r}", where)
    return values


def fault_entry(err) -> dict:
    """A fault of :func:`scan` as a record (for a build's metadata): ``file``, ``airspace``
    (its ``AN`` name, or None), ``line`` and ``problem``."""
    return {
        "file": err.path,
        "airspace": getattr(err, "airspace", None),
        "line": getattr(err, "line", None),
        "problem": err.message,
    }


def _fault(path, space, line, message):
    err = InputError(path, message, space.label(line) if space else f"line {line}")
    err.airspace, err.line = (space.name if space else None), line
    return err


def scan(path, skipped=None):
    """Every airspace of an OpenAir file read as far as it can be, and every fault found.

    A limit without a numeric meaning (``NOTAM``, ``BCTA FT``) is widened: a floor to the
    ground, a ceiling to unlimited, and a note says so. An airspace with a record that cannot
    be read, or that is no area, is left out of the volumes and its faults listed.

    Parameters
    ----------
    path : str or Path
    skipped : collections.Counter, optional
        Airways (``DY``) are counted here and left out; without it they are faults.

    Returns
    -------
    volumes : list of tuple
        As :mod:`alphafence.zones.airspace` takes them.
    faults : list of InputError
        In the order of the file's lines, each naming the file, the airspace (``AN``) and the
        line; :func:`fault_entry` makes them records.
    widened : dict
        Volume source -> its airspace, for those with a limit widened (:func:`widened_notes`).
    """
    spaces, space, faults = [], None, []
    for number, raw in enumerate(_text(path).splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("*"):
            continue
        cmd, _, arg = line.partition(" ")
        cmd = cmd.upper()
        if cmd == "AC":
            space = _Airspace(len(spaces), number, arg.split("*")[0].strip() or "UNC")
            spaces.append(space)
        elif cmd[:1] not in ("A", "D", "V"):
            continue  # SP, SB pens and brushes; TO, TC terrain
        elif space is None:
            faults.append(_fault(path, None, number, f"{cmd} before the first AC record"))
        else:
            try:
                _record(path, f"line {number}", number, space, cmd, arg)
            except InputError as exc:
                space.faults.append((number, exc.message))  # named once AN is read
    volumes, widened = [], {}
    for s in spaces:
        faults.extend(_fault(path, s, line, message) for line, message in s.faults)
        if s.faults:
            continue
        try:
            volume = _volume(path, s, skipped)
        except InputError as exc:
            faults.append(_fault(path, s, s.line, exc.message))
            continue
        if volume is not None:
            volumes.append(volume)
            if s.unread:
                widened[volume[2]] = s
    faults.sort(key=lambda e: e.line)
    return volumes, faults, widened


def _record(path, where, number, space, cmd, arg):
    """Read one record of an airspace into it."""
    if cmd == "AN":
        space.name = arg.strip() or None
    elif cmd == "AY":
        space.type = arg.split("*")[0].strip() or None
    elif cmd in ("AL", "AH"):
        try:
            value = read_altitude(arg)
            space.unread.pop(cmd, None)
        except Unreadable as exc:
            value = _LIMITS[cmd][1]
            space.unread[cmd] = (number, arg.split("*")[0].strip(), str(exc))
        if cmd == "AL":
            space.lower = value
        else:
            space.upper = value
    elif cmd == "V":
        _variable(path, where, space, arg)
    elif cmd == "DP":
        space.parts.append(("P", *parse_coordinates(path, where, arg, 1)[0]))
    elif cmd in ("DA", "DB", "DC"):
        _arc(path, where, space, cmd, arg)
    elif cmd == "DY":
        space.airway = True


def _raise(path, faults):
    if len(faults) == 1:
        raise faults[0]
    if faults:
        raise InputErrors(path, faults)


def read_volumes(path, skipped=None, notes=None):
    """The airspaces of an OpenAir file as volumes (see :mod:`alphafence.zones.airspace`),
    all of them or none.

    Parameters
    ----------
    path : str or Path
    skipped : collections.Counter, optional
        Airways (``DY``) are counted here and left out; without it they are refused.
    notes : list, optional
        Notes on limits that were widened (:func:`scan`) are appended.

    Returns
    -------
    list of tuple

    Raises
    ------
    InputError
        Naming the airspace and line that is malformed; :class:`InputErrors` when there are
        several, one line each.
    """
    volumes, faults, widened = scan(path, skipped)
    _raise(path, faults)
    if notes is not None:
        notes.extend(
            n for v in volumes if v[2] in widened for n in widened_notes(path, widened[v[2]])
        )
    return volumes


def _variable(path, where, space, arg):
    key, _, value = arg.partition("=")
    key = key.strip().upper()
    if key == "X":
        space.centre = parse_coordinates(path, where, value, 1)[0]
    elif key == "D":
        direction = value.split("*")[0].strip()
        if direction not in ("+", "-"):
            raise InputError(path, f"V D= must be + or -, not {direction!r}", where)
        space.cw = direction == "+"
    # W (airway width) and Z (zoom) do not change the outline


def _arc(path, where, space, cmd, arg):
    if space.centre is None:
        raise InputError(path, f"{cmd} without a centre (V X=) in this airspace", where)
    if cmd == "DC":
        (radius,) = _numbers(path, where, arg, 1)
        if not radius > 0:
            raise InputError(path, "DC radius must be positive", where)
        space.circle = (*space.centre, radius * NM)
    elif cmd == "DA":
        radius, a0, a1 = _numbers(path, where, arg, 3)
        space.parts.append(
            arc_from_angles(path, where, space.centre, radius * NM, a0, a1, space.cw)
        )
    else:
        start, end = parse_coordinates(path, where, arg, 2)
        space.parts.append(arc_from_points(path, where, space.centre, start, end, space.cw))


def read_openair(path, rules, repaired, skipped, notes=None, invalid=None):
    """The restricted features of an OpenAir file: one per airspace, matched against
    ``rules`` by its pseudo-tags ``airspace:format`` (``openair``), ``airspace:class`` (the
    ``AC`` class), ``airspace:type`` (``AY``) and ``name`` (``AN``); the band from ``AL``/``AH``
    in metres, its references kept.

    A limit without a numeric meaning widens a keep-out's (or warning's) band, with a note;
    a keep-in's band cannot be widened safely, so that is a fault of its airspace.

    Parameters
    ----------
    path : str or Path
    rules : Rules
    repaired : list
    skipped : collections.Counter
        As :func:`alphafence.zones.airspace.features_from_volumes` takes them.
    notes : list, optional
        Notes on widened limits are appended, one line each.
    invalid : list, optional
        When given, the airspaces with a fault are left out and described here
        (:func:`fault_entry`); when None, any fault is raised.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        Naming the airspace and line at fault; :class:`InputErrors` listing every fault of
        the file, one line each, when there are several.
    """
    volumes, faults, widened = scan(path, skipped)
    features = features_from_volumes(path, volumes, rules, repaired, skipped, "OpenAir airspace")
    kept = []
    for f in features:
        space = widened.get(f.source)
        if space is None or f.kind != "keep_in":
            kept.append(f)
            continue
        for cmd, (line, text, why) in sorted(space.unread.items(), key=lambda kv: kv[1]):
            limit = _LIMITS[cmd][0]
            message = f"{cmd} {text!r} is not read ({why}): a keep-in's {limit} cannot be widened"
            faults.append(_fault(path, space, line, message))
    faults.sort(key=lambda e: e.line)
    if invalid is None:
        _raise(path, faults)
    else:
        invalid.extend(fault_entry(e) for e in faults)
    if notes is not None:
        notes.extend(
            n for f in kept if f.source in widened for n in widened_notes(path, widened[f.source])
        )
    return kept
