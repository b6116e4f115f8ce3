"""OpenAir airspace files (WinPilot's format, extended by Naviter; the gliding and ultralight
community's airspace files).

An airspace starts at ``AC class``; ``AN`` names it, ``AY`` types it, ``AL``/``AH`` give its
floor and ceiling (``SFC``/``GND``, ``UNL``, ``FL65``, ``1500ft AGL``, ``600m MSL``...; feet
when no unit). Its outline: ``DP`` points, ``DA radius, start, end`` and ``DB point, point``
arcs about the centre ``V X=`` in the direction ``V D=+`` (clockwise, the default, reset at each
``AC``) or ``-``, ``DC radius`` circles; distances in nautical miles, coordinates in degrees,
minutes and seconds (``52:13:05 N 001:35:03 W``) or decimal minutes. Arcs and circles are drawn
outward: a convex arc by tangents outside it, a concave one (the airspace outside its circle)
by chords inside it, so the polygon never cuts into the airspace.
"""

from __future__ import annotations

import math
import re

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.formats.airspace import (
    PAD_M,
    arc_step,
    circle_polygon,
    circumscribed_points,
    features_from_volumes,
    fences_from_volumes,
)
from alphafence.formats.jsonfile import max_json_bytes, read_limited
from alphafence.geo.frame import LocalFrame

NM = 1852.0
FT = 0.3048
SUFFIXES = (".openair",)
_COORD = re.compile(r"(\d+(?:\.\d+)?)(?::(\d+(?:\.\d+)?))?(?::(\d+(?:\.\d+)?))?\s*([NSEWnsew])")
_ALT = re.compile(
    r"^(\d+(?:\.\d+)?)(FT|F|FEET|M|MTR|METERS?)?(AGL|AMSL|MSL|GND|SFC|ASFC|AGND|ALT|STD)?$"
)
_GROUND = ("SFC", "GND", "GROUND")
_UNLIMITED = ("UNL", "UNLIM", "UNLIMITED", "UNLTD")
_REFERENCE = {"AGL": "AGL", "GND": "AGL", "SFC": "AGL", "ASFC": "AGL", "AGND": "AGL"}
_REFERENCE.update({"AMSL": "AMSL", "MSL": "AMSL", "ALT": "AMSL", "STD": "STD", None: "AMSL"})


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


def parse_coordinates(path, where, text, count):
    """``count`` positions ``(lon, lat)`` from OpenAir text: latitude (N/S) then longitude
    (E/W) each, as ``DD:MM:SS``, ``DD:MM.mmm`` or decimal degrees.

    Examples
    --------
    >>> parse_coordinates("f", "line 1", "51:30:00 N 000:07:30 W", 1)
    [(-0.125, 51.5)]
    >>> parse_coordinates("f", "line 2", "51:30.500N 000:07.500E, 51:31N 0:08E", 2)
    [(0.125, 51.50833333333333), (0.13333333333333333, 51.516666666666666)]
    """
    found = _COORD.findall(text)
    if len(found) != 2 * count:
        raise InputError(path, f"expected {count} lat/lon position(s), got {text.strip()!r}", where)
    out = []
    for k in range(count):
        lat = _degrees(path, where, found[2 * k], "NS", 90.0)
        lon = _degrees(path, where, found[2 * k + 1], "EW", 180.0)
        out.append((lon, lat))
    return out


def _degrees(path, where, parts, hemispheres, limit):
    deg, minutes, seconds, hemi = parts
    if hemi.upper() not in hemispheres:
        raise InputError(path, f"expected {'/'.join(hemispheres)} in {''.join(parts)!r}", where)
    m, s = float(minutes or 0), float(seconds or 0)
    if m >= 60 or s >= 60 or (seconds and "." in minutes):
        raise InputError(path, f"minutes and seconds must be below 60: {':'.join(parts)}", where)
    value = float(deg) + m / 60.0 + s / 3600.0
    if value > limit:
        raise InputError(path, f"{value:g} degrees is out of range", where)
    return -value if hemi.upper() in "SW" else value


def parse_altitude(path, where, text):
    """An OpenAir limit -> ``(metres or None, reference)``; None for unlimited, the reference
    ``"AGL"``, ``"AMSL"`` or ``"STD"`` (flight levels).

    Examples
    --------
    >>> parse_altitude("f", "AL", "SFC"), parse_altitude("f", "AH", "FL 65")
    ((0.0, 'AGL'), (1981.2, 'STD'))
    >>> parse_altitude("f", "AH", "1500ft AGL"), parse_altitude("f", "AH", "600 m MSL")
    ((457.2, 'AGL'), (600.0, 'AMSL'))
    """
    t = "".join(text.split("*")[0].upper().split())
    if t in _GROUND:
        return 0.0, "AGL"
    if t in _UNLIMITED:
        return None, "AMSL"
    fl = re.match(r"^FL(\d+(?:\.\d+)?)(STD)?$", t)
    if fl:
        return round(float(fl.group(1)) * 100 * FT, 3), "STD"
    m = _ALT.match(t)
    if not m:
        raise InputError(path, f"cannot read the altitude {text.strip()!r}", where)
    unit = 1.0 if (m.group(2) or "FT").startswith("M") else FT
    return round(float(m.group(1)) * unit, 3), _REFERENCE[m.group(3)]


class _Airspace:
    """One airspace as its records are read."""

    def __init__(self, line, cls):
        self.line, self.cls = line, cls
        self.name = self.type = None
        self.lower = (0.0, "AGL")
        self.upper = (None, "AMSL")
        self.parts = []  # ("P", lon, lat) or ("A", centre, r0, b0, r1, b1, cw, sweep, start, end)
        self.circle = None
        self.centre = None
        self.cw = True
        self.airway = False


def _arc_from_points(path, where, centre, start, end, cw):
    frame = LocalFrame(*centre)
    x, y = frame.to_local(np.array([start[0], end[0]]), np.array([start[1], end[1]]))
    r0, r1 = float(math.hypot(x[0], y[0])), float(math.hypot(x[1], y[1]))
    if min(r0, r1) <= 0:
        raise InputError(path, "an arc's end lies on its centre", where)
    b0, b1 = math.degrees(math.atan2(x[0], y[0])), math.degrees(math.atan2(x[1], y[1]))
    sweep = ((b1 - b0) if cw else (b0 - b1)) % 360.0
    return ("A", centre, r0, b0, r1, b1, cw, sweep, start, end)


def _arc_from_angles(path, where, centre, radius_m, a0, a1, cw):
    if not radius_m > 0:
        raise InputError(path, "an arc's radius must be positive", where)
    sweep = ((a1 - a0) if cw else (a0 - a1)) % 360.0
    if sweep == 0 and a0 != a1:
        sweep = 360.0
    frame = LocalFrame(*centre)
    b = np.radians([a0, a1])
    lons, lats = frame.to_wgs84(radius_m * np.sin(b), radius_m * np.cos(b))
    start, end = (float(lons[0]), float(lats[0])), (float(lons[1]), float(lats[1]))
    return ("A", centre, radius_m, a0, radius_m, a1, cw, sweep, start, end)


def _arc_points(arc, convex, exact):
    """Positions of an arc from its start to its end: sampled on the true arc (``exact``),
    outside it (``convex``: tangents) or inside it (chords)."""
    _, centre, r0, b0, r1, b1, cw, sweep, start, end = arc
    if sweep == 0:
        return [start, end]
    sign = 1.0 if cw else -1.0
    rmax, rmin = max(r0, r1), min(r0, r1)
    step = arc_step(rmax)
    n = max(1, math.ceil(sweep / step))
    step = sweep / n
    if exact:
        k = np.arange(1, n)
        radii = r0 + (r1 - r0) * k / n
        b = np.radians(b0 + sign * k * step)
        xy = np.column_stack([radii * np.sin(b), radii * np.cos(b)])
    elif convex:
        xy = circumscribed_points(rmax, b0 + sign * (np.arange(n) + 0.5) * step, step)
    else:
        b = np.radians(b0 + sign * np.arange(1, n) * step)
        r = max(rmin - PAD_M, 0.0)
        xy = np.column_stack([r * np.sin(b), r * np.cos(b)])
    lons, lats = LocalFrame(*centre).to_wgs84(xy[:, 0], xy[:, 1])
    return [start, *zip(np.atleast_1d(lons).tolist(), np.atleast_1d(lats).tolist()), end]


def _outline(parts, exact=False, ring_cw=None):
    pts = []
    for part in parts:
        if part[0] == "P":
            pts.append(part[1:])
        else:
            convex = ring_cw is None or part[6] == ring_cw
            pts.extend(_arc_points(part, convex, exact))
    return [p for i, p in enumerate(pts) if i == 0 or p != pts[i - 1]]


def _polygon(path, where, space):
    """The airspace's polygon, arcs drawn outward (by the ring's orientation)."""
    if space.circle is not None:
        if space.parts:
            raise InputError(path, "a DC circle cannot be combined with DP, DA or DB", where)
        lon, lat, r = space.circle
        return circle_polygon(lon, lat, r), {"circle": [lon, lat, r]}
    sampled = _outline(space.parts, exact=True)
    if len(set(sampled)) < 3:
        raise InputError(path, "needs at least 3 distinct points (DP, DA, DB) or a DC", where)
    ring_cw = not shapely.LinearRing(sampled).is_ccw
    pts = _outline(space.parts, ring_cw=ring_cw)
    return shapely.Polygon(pts), {}


def _volume(path, n, space, skipped):
    where = f"airspace {n} ({space.name or space.cls}, line {space.line})"
    if space.airway:
        if skipped is None:
            raise InputError(path, "airway segments (DY) are not read", where)
        skipped["OpenAir airway (DY) segments, not read"] += 1
        return None
    if not space.parts and space.circle is None:
        raise InputError(path, "an airspace without DP, DA, DB or DC records", where)
    geom, props = _polygon(path, where, space)
    (lower, lref), (upper, uref) = space.lower, space.upper
    if lower is not None and upper is not None and lref == uref and upper <= lower:
        raise InputError(path, f"AH {upper:g} m is not above AL {lower:g} m", where)
    tags = {"airspace:format": "openair", "airspace:class": space.cls}
    if space.type:
        tags["airspace:type"] = space.type
    if space.name:
        tags["name"] = space.name
    props.update(lower_reference=lref, upper_reference=uref, airspace_class=space.cls)
    return geom, tags, f"openair/{n}", lower, upper, props


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


def read_volumes(path, skipped=None):
    """The airspaces of an OpenAir file as volumes (see :mod:`alphafence.formats.airspace`).

    Parameters
    ----------
    path : str or Path
    skipped : collections.Counter, optional
        Airways (``DY``) are counted here and left out; without it they are refused.

    Returns
    -------
    list of tuple

    Raises
    ------
    InputError
        One line naming the airspace (or line) that is malformed.
    """
    spaces, space = [], None
    for number, raw in enumerate(_text(path).splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("*"):
            continue
        where = f"line {number}"
        cmd, _, arg = line.partition(" ")
        cmd = cmd.upper()
        if cmd == "AC":
            space = _Airspace(number, arg.split("*")[0].strip() or "UNC")
            spaces.append(space)
            continue
        if cmd[:1] not in ("A", "D", "V"):
            continue  # SP, SB pens and brushes; TO, TC terrain
        if space is None:
            raise InputError(path, f"{cmd} before the first AC record", where)
        if cmd == "AN":
            space.name = arg.strip() or None
        elif cmd == "AY":
            space.type = arg.split("*")[0].strip() or None
        elif cmd in ("AL", "AH"):
            value = parse_altitude(path, where, arg)
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
    volumes = []
    for n, s in enumerate(spaces):
        volume = _volume(path, n, s, skipped)
        if volume is not None:
            volumes.append(volume)
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
            _arc_from_angles(path, where, space.centre, radius * NM, a0, a1, space.cw)
        )
    else:
        start, end = parse_coordinates(path, where, arg, 2)
        space.parts.append(_arc_from_points(path, where, space.centre, start, end, space.cw))


def read_openair(path, rules, repaired, skipped):
    """The restricted features of an OpenAir file: one per airspace, matched against
    ``rules`` by its pseudo-tags ``airspace:format`` (``openair``), ``airspace:class`` (the
    ``AC`` class), ``airspace:type`` (``AY``) and ``name`` (``AN``); the band from ``AL``/``AH``
    in metres, its references kept.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        One line naming the airspace (or line) that is malformed.
    """
    volumes = read_volumes(path, skipped)
    return features_from_volumes(path, volumes, rules, repaired, skipped, "OpenAir airspace")


def read_openair_fences(path):
    """The airspaces of an OpenAir file as keep-out fences (their bands kept).

    Returns
    -------
    list of FenceRecord
    """
    return fences_from_volumes(path, read_volumes(path), "openair")
