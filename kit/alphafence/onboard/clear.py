"""Points the onboard fence must leave clear: the vehicle's home and, in the air, its position.

An autopilot reads its fence against home before anything flies: ArduPilot refuses to arm in
an exclusion or outside its inclusions, and PX4 discards, as the fence loads, every area that
home breaches (:mod:`alphafence.onboard.rules`). A compiled fence is not the fences it stands
for: a keep-out fence is simplified outward, replaced by a circle, or merged with its
neighbours, and any of these may reach over home although no fence does. The compiler
therefore takes home (and the position) as constraints, as it takes containment: no option it
chooses for a keep-out fence comes within :data:`CLEARANCE_M` of them (less only where the
fence itself comes nearer: it may come as near as the fence less twice the pad), no merge
spans them, and a keep-in fence that holds them is stored so that it still holds them that far
inside. Only a fence that itself holds a point (a keep-out fence over home, home outside every
keep-in fence) is refused, by its name (:meth:`LocalClear.check_zone`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.onboard import HOME_CLEARANCE_M
from alphafence.onboard.options import EXACT_MITRE_LIMIT, PAD_M

CLEARANCE_M = HOME_CLEARANCE_M  # no compiled keep-out item comes nearer home than this
TOUCH_M = 2 * PAD_M  # a keep-out fence this near a point holds it (its pad reaches over it)
# what the metric shapes the compiler chooses among may differ from the items as the autopilot
# reads them: a circle's radius is stored for the autopilot's own distance (ArduPilot's
# constant degree length is 0.67 % long at the equator), an edge bows in lon/lat
CIRCLE_READ = 1.01  # a circle item reaches at most this many times its metric radius
READ_SLACK_M = 1.0  # and the clearance is sought this much wider, where there is room


@dataclass(frozen=True)
class ClearPoint:
    """A point the onboard fence must leave clear.

    Attributes
    ----------
    label : str
        What it is, for messages: ``"home"``, ``"the vehicle's position"``.
    lon, lat : float
        Degrees (WGS84).
    strict : bool
        A fence that holds it is refused; else (a position in flight, which may be in breach)
        such a fence only constrains nothing there.
    """

    label: str
    lon: float
    lat: float
    strict: bool = True

    def __str__(self) -> str:
        return f"{self.label} ({self.lat:.7f},{self.lon:.7f})"


@dataclass(frozen=True)
class KeepClear:
    """The points a compilation leaves clear, and how far.

    Attributes
    ----------
    points : tuple of ClearPoint
    clearance_m : float
        The least distance between a point and a compiled keep-out item, or a compiled
        keep-in item's edge (where the fence itself leaves that much).
    """

    points: tuple
    clearance_m: float = CLEARANCE_M

    @classmethod
    def of(cls, home=None, position=None, clearance_m: float = CLEARANCE_M, strict=True):
        """From ``(lon, lat)`` tuples (either may be None); None when both are. ``strict``:
        a fence that holds home is refused (in flight it is not: a zone may come over home
        while the vehicle is away). A fence that holds the position never is."""
        points = [ClearPoint(label, *p, strict=k) for label, p, k in
                  (("home", home, strict), ("the vehicle's position", position, False))
                  if p is not None]  # fmt: skip
        return cls(tuple(points), float(clearance_m)) if points else None

    def local(self, frame) -> LocalClear:
        """The points in ``frame`` (metric)."""
        return LocalClear(self, frame)


class LocalClear:
    """:class:`KeepClear` in a compilation's metric frame.

    Parameters
    ----------
    keep : KeepClear
    frame : LocalFrame
    """

    def __init__(self, keep: KeepClear, frame):
        self.keep = keep
        lon = np.array([p.lon for p in keep.points], float)
        lat = np.array([p.lat for p in keep.points], float)
        x, y = frame.to_local(lon, lat)
        self.points = shapely.points(np.asarray(x, float), np.asarray(y, float))
        self.free = np.ones(len(keep.points), bool)  # no fence holds it (a position may be held)

    def check_zone(self, source, site, local, inclusion: bool) -> None:
        """Refuse a keep-out fence that holds a point (or comes within :data:`TOUCH_M`).

        Raises
        ------
        InputError
            ``hospital/way/1 (St Mary's): home (35.9,14.5) is inside this keep-out fence:
            ...``.
        """
        if inclusion:
            return
        d = shapely.distance(local, self.points)
        self.free &= d >= TOUCH_M
        for k in np.flatnonzero(d < TOUCH_M):
            if not self.keep.points[k].strict:
                continue
            where = "inside" if d[k] == 0 else f"{d[k]:.2f} m from"
            raise InputError(
                source,
                f"{site}: {self.keep.points[k]} is {where} this keep-out fence: the vehicle "
                "would refuse to arm there (PX4 would drop the fence); move home or leave the "
                "fence out",
            )

    def check_keep_in(self, source, kept) -> None:
        """Refuse keep-in fences of which a point lies in none (``kept``: ``[(site,
        local)]``, the real fences)."""
        if not kept:
            return
        geoms = np.array([g for _, g in kept], dtype=object)
        for k, pt in enumerate(self.points):
            inside = shapely.covers(geoms, pt).any()
            self.free[k] &= inside
            if self.keep.points[k].strict and not inside:
                names = ", ".join(s for s, _ in kept[:3]) + (", ..." if len(kept) > 3 else "")
                raise InputError(
                    source,
                    f"{self.keep.points[k]} is outside every keep-in fence ({names}): the "
                    "vehicle would refuse to arm there (PX4 would drop the fence); move home "
                    "or leave the keep-in fences out",
                )

    def needs(self, real, inclusion: bool) -> np.ndarray:
        """How far each point must stay from what is stored for the fence ``real`` (metric):
        the clearance, or less where the fence itself comes nearer; NaN where a keep-in fence
        does not hold the point (it constrains nothing there)."""
        c = self.keep.clearance_m + READ_SLACK_M
        if inclusion:
            inside = shapely.covers(real, self.points)
            d = shapely.distance(shapely.boundary(real), self.points)
            return np.where(inside, np.minimum(c, d - TOUCH_M), np.nan)
        return np.minimum(c, shapely.distance(real, self.points) - TOUCH_M)

    def allows(self, shape, needs, inclusion: bool, circle=None) -> bool:
        """Whether a stored ``shape`` (metric; a keep-out ``circle`` ``(x, y, r)`` read as the
        autopilot may read it) leaves each point its ``needs``."""
        if circle is not None and not inclusion:
            x, y, r = circle
            d = shapely.distance(shapely.Point(x, y), self.points) - (r * CIRCLE_READ + 0.1)
            return bool((d >= needs - 1e-6).all())
        if inclusion:
            on = ~np.isnan(needs)
            if not on.any():
                return True
            pts = self.points[on]
            d = shapely.distance(shapely.boundary(shape), pts)
            return bool(shapely.covers(shape, pts).all() and (d >= needs[on] - 1e-6).all())
        return bool((shapely.distance(shape, self.points) >= needs - 1e-6).all())

    def fit(self, piece) -> bool:
        """Keep only ``piece``'s options that leave the points clear (in place); whether any
        is left."""
        real = piece.local if piece.required is None else piece.required
        needs = self.needs(real, piece.inclusion)
        piece.options = [o for o in piece.options
                         if self.allows(o.local, needs, piece.inclusion, o.circle)]  # fmt: skip
        piece.choice = min(piece.choice, max(len(piece.options) - 1, 0))
        return bool(piece.options)

    def spans(self, hulls, needs) -> np.ndarray:
        """For merges: whether each candidate ``hulls`` (metric, what a merge may fill) comes
        nearer a point than ``needs`` (one row of needs per hull) and the most its padded
        corners reach out."""
        d = shapely.distance(np.asarray(hulls, dtype=object)[:, None], self.points[None, :])
        return (d < needs + EXACT_MITRE_LIMIT * PAD_M).any(axis=1)


def check_held(items, clear: LocalClear | None, union=False, source: str = "compile") -> None:
    """Refuse compiled ``items`` that, as the autopilot reads them, breach a point no fence
    holds (:attr:`LocalClear.free`): an exclusion over it, an inclusion without it (under
    the ``union`` rule: no inclusion with it).

    Raises
    ------
    InputError
        Naming the point and the item.
    """
    if clear is None:
        return
    from alphafence.mavlink.inclusions import inclusion_count
    from alphafence.onboard.rules import areas_breached_at

    for p, free in zip(clear.keep.points, clear.free):
        if not free:
            continue
        hit = areas_breached_at(items, p.lon, p.lat)
        if union and sum(a.inclusion for a in hit) < inclusion_count(items):
            hit = [a for a in hit if not a.inclusion]  # it is inside one of them
        if hit:
            raise InputError(
                source,
                f"the compiled {hit[0].name} breaches {p}, as the vehicle reads it; compile "
                "with a smaller --home-clearance, or narrow the area",
            )
