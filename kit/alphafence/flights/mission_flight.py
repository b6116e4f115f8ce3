"""A mission's items flown: the positions in the order flown, jumps followed, and the
altitudes of each leg as ArduPilot flies them (:mod:`alphafence.flights.mission` reads the files).

``DO_JUMP`` and ``DO_JUMP_TAG`` are followed as ArduPilot runs them (the jump taken its repeat
count of times, then passed; -1 for ever), with a bound: a jump loop that runs for ever is flown
until it repeats, and after :data:`MAX_POSITIONS` positions every jump left is passed (the legs
a loop flies again are legs already flown).

Each position has the altitude profile of the leg flown to it (:class:`Waypoint`), in the
reference of the items' frame: ``MAV_FRAME_GLOBAL_RELATIVE_ALT`` (``_INT``) above home,
``MAV_FRAME_GLOBAL`` (``_INT``) AMSL (taken above home where home's altitude AMSL is known),
``MAV_FRAME_GLOBAL_TERRAIN_ALT`` (``_INT``) above the terrain. Altitudes change linearly along
a leg; an altitude of 0 or none holds the current one (as ArduCopter does). A takeoff climbs
where the vehicle is, then flies to its position (if any) at that altitude; a landing flies to
its position at the current altitude, then descends to the ground (0 above home, or above the
terrain); RTL climbs to the larger of the current altitude and ``rtl_alt_m`` (ArduCopter's
``RTL_ALT``, 15 m by default), flies home at it and lands there. A climb or descent without a
position of its own is flown where the vehicle is, at the start of the next leg (or as a last
leg of its own, where the vehicle is). A leg whose altitudes are in two references, or in a
frame of none of these, has no profile (its altitude is not known).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from alphafence.errors import InputError
from alphafence.mavlink import ids

MAX_POSITIONS = 10_000
"""Positions flown before every jump still to come is passed instead of taken (a loop flown
again flies legs already flown; the bound keeps a flight path that ``compile --area`` buffers
short)."""

JUMPS = (ids.MAV_CMD_DO_JUMP, ids.MAV_CMD_DO_JUMP_TAG)
RTL_ALT_M = 15.0
"""The altitude above home RTL climbs to at least (ArduCopter's ``RTL_ALT`` default)."""

FRAMES = {  # a mission item's frame -> the reference of its altitude
    ids.MAV_FRAME_GLOBAL: "amsl",
    ids.MAV_FRAME_GLOBAL_INT: "amsl",
    ids.MAV_FRAME_GLOBAL_RELATIVE_ALT: "home",
    ids.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "home",
    ids.MAV_FRAME_GLOBAL_TERRAIN_ALT: "terrain",
    ids.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: "terrain",
}
TAKEOFFS = (ids.MAV_CMD_NAV_TAKEOFF, ids.MAV_CMD_NAV_VTOL_TAKEOFF)
LANDINGS = (ids.MAV_CMD_NAV_LAND, ids.MAV_CMD_NAV_VTOL_LAND)
UNKNOWN = (None, None)  # an altitude not known: (altitude, reference)


@dataclass
class Waypoint:
    """A position a mission flies through.

    Attributes
    ----------
    label : str
        Where it came from, for messages (``"home"``, ``"item 3 (waypoint)"``).
    lon, lat : float
        Degrees.
    alt : float or None
        The altitude on arrival in ``frame`` (None: not known).
    frame : str or None
        The reference of ``alt`` and ``profile``: ``"home"`` (above home), ``"amsl"`` (only
        where home's altitude AMSL is not known), ``"terrain"`` (above the terrain below);
        None: not known.
    profile : tuple
        The altitudes of the leg flown to it: ``((fraction of the leg, altitude), ...)``, in
        order, linear between them (a fraction twice: a climb or descent there); empty when
        not known (the first position, or altitudes in two references).
    """

    label: str  # "home", "item 3 (waypoint)", "seq 4 (takeoff)"
    lon: float
    lat: float
    alt: float | None = None
    frame: str | None = None
    profile: tuple = ()


@dataclass(frozen=True)
class Step:
    """One mission item as the flight follows it (``where`` and ``label`` name it in
    messages; ``key`` is what a DO_JUMP names: the doJumpId in plans, the seq in WPL files)."""

    where: str  # for messages: "item 5", "line 7"
    label: str
    command: int
    position: tuple | None  # (lon, lat)
    p1: float
    p2: float
    key: int | None  # what a DO_JUMP names: the doJumpId (plans) or the seq (WPL)
    frame: int | None = None  # MAV_FRAME of its altitude
    alt: float = math.nan  # param 7


def _whole(v):
    return math.isfinite(v) and v == int(v)


def _targets(path, steps, key_name):
    """Where each jump goes: the step a DO_JUMP's param1 names (by ``key_name``), or the
    JUMP_TAG a DO_JUMP_TAG's param1 names."""
    by_key, tags = {}, {}
    for i, s in enumerate(steps):
        if s.key is not None:
            by_key.setdefault(s.key, i)
        if s.command == ids.MAV_CMD_JUMP_TAG and _whole(s.p1):
            tags.setdefault(int(s.p1), i)
    out = {}
    for i, s in enumerate(steps):
        if s.command not in JUMPS:
            continue
        word = "DO_JUMP" if s.command == ids.MAV_CMD_DO_JUMP else "DO_JUMP_TAG"
        if not _whole(s.p1):
            raise InputError(path, f"{word} target must be a whole number, not {s.p1:g}", s.where)
        t = int(s.p1)
        if s.command == ids.MAV_CMD_DO_JUMP_TAG:
            if t not in tags:
                raise InputError(path, f"DO_JUMP_TAG to tag {t}: no JUMP_TAG {t}", s.where)
            out[i] = tags[t]
        elif key_name == "seq" and t == 0:
            raise InputError(
                path, "DO_JUMP to seq 0 (home): ArduPilot jumps to mission items only", s.where
            )
        elif t not in by_key:
            raise InputError(path, f"DO_JUMP to {key_name} {t}: no such item", s.where)
        else:
            out[i] = by_key[t]
    return out


def _repeats(p2) -> float:
    """How often a jump is taken: its repeat count; -1 (any negative, or no number) for ever."""
    return float(int(p2)) if math.isfinite(p2) and p2 >= 0 else math.inf


def _target(s, cur, home_amsl):
    """``(altitude, reference)`` a step flies to: param 7 in its frame (AMSL above home where
    home's altitude AMSL is known); 0 or none: the current altitude ``cur``."""
    if not math.isfinite(s.alt) or s.alt == 0:
        return cur
    ref = FRAMES.get(s.frame)
    if ref == "amsl" and home_amsl is not None:
        return s.alt - home_amsl, "home"
    return (s.alt, ref) if ref is not None else UNKNOWN


class _Height:
    """The altitude as the flight goes: the current one and the range climbed or descended
    through where the vehicle is since its last position (all in one reference, or not known).
    """

    def __init__(self):
        self.cur = (0.0, "home")  # on the ground at home
        self.span = ("home", 0.0, 0.0)

    def key(self):
        return (self.cur, self.span)

    def move(self, alt_ref):
        """A climb or descent where the vehicle is."""
        ref, lo, hi = self.span
        alt, to = alt_ref
        self.cur = alt_ref
        ok = ref is not None and to == ref and alt is not None
        self.span = (ref, min(lo, alt), max(hi, alt)) if ok else (None, None, None)

    def ground(self):
        """Where a landing ends: 0 above home or above the terrain."""
        return (0.0, self.cur[1]) if self.cur[1] in ("home", "terrain") else UNKNOWN

    def leg(self, label, lon, lat, points):
        """The waypoint at the end of a leg flown after the climbs here: ``points`` are
        ``(fraction, (altitude, reference))`` along it."""
        ref, lo, hi = self.span
        prof = [(0.0, lo), (0.0, hi), (0.0, self.cur[0])] + [(t, a) for t, (a, _) in points]
        refs = {ref, self.cur[1]} | {r for _, (_, r) in points}
        if len(refs) != 1 or None in refs or any(a is None for _, a in prof):
            prof, ref = (), None
        prof = tuple(p for k, p in enumerate(prof) if k == 0 or p != prof[k - 1])
        end = points[-1][1]
        self.cur = end
        self.span = (end[1], end[0], end[0]) if end[0] is not None else (None, None, None)
        return Waypoint(label, lon, lat, end[0], ref, prof)


def fly(path, steps, home, key_name, home_amsl=None, rtl_alt_m=RTL_ALT_M):
    """The positions flown, in order, following the jumps, with their altitudes (see the
    module).

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    steps : list of Step
        The mission's items in order.
    home : Waypoint or None
        Home, where the file gives it apart from the items (else the first position).
    key_name : str
        What a DO_JUMP's param 1 names (``"doJumpId"`` or ``"seq"``), for messages.
    home_amsl : float, optional
        Home's altitude AMSL: AMSL altitudes are then taken above home.
    rtl_alt_m : float
        The altitude above home RTL climbs to at least.

    Returns
    -------
    list of Waypoint
    """
    targets = _targets(path, steps, key_name)
    out = [home] if home is not None else []
    h = _Height()
    left, seen, i, moved = {}, set(), 0, None
    while i < len(steps):
        s = steps[i]
        if i in targets:
            n = left.setdefault(i, _repeats(s.p2))
            if len(out) >= MAX_POSITIONS and n != math.inf:
                n = 0
            if n > 0:
                left[i] = n - 1
                last = (out[-1].label, out[-1].lon, out[-1].lat) if out else None
                state = (i, last, h.key(), tuple(sorted(left.items())))
                if state in seen:  # flown exactly so before: the same legs from here on
                    break
                seen.add(state)
                i = targets[i]
                continue
        elif s.command == ids.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            if home is not None:
                alt, ref = h.cur
                top = (max(alt, rtl_alt_m), ref) if ref == "home" else UNKNOWN
                pts = [(0.0, top), (1.0, top), (1.0, (0.0, "home"))]
                out.append(h.leg(f"{s.label} -> home", home.lon, home.lat, pts))
                moved = None
        elif s.position is not None:
            if s.command in LANDINGS:
                pts = [(1.0, h.cur), (1.0, h.ground())]
            elif s.command in TAKEOFFS:
                to = _target(s, h.cur, home_amsl)
                pts = [(0.0, to), (1.0, to)]
            else:
                pts = [(1.0, _target(s, h.cur, home_amsl))]
            out.append(h.leg(s.label, *s.position, pts))
            moved = None
            if home is None:
                home = out[-1]
        elif ids.flies_to_position(s.command):  # a climb or descent where the vehicle is
            to = h.ground() if s.command in LANDINGS else _target(s, h.cur, home_amsl)
            moved = s.label if to != h.cur else moved
            h.move(to)
        i += 1
    if moved is not None and out:  # the last climb or descent, where the vehicle is
        out.append(h.leg(moved, out[-1].lon, out[-1].lat, [(1.0, h.cur)]))
    return out
