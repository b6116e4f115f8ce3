"""The ways one fence can be stored onboard: a circle, or a polygon of k vertices simplified
*outward* (keep-out: the onboard fence still contains the fence) or *inward* (keep-in: it stays
inside), each with what it costs in storage and in area."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.fencing.fences import circle_polygon, enclosing_circle
from alphafence.geo.alpha import outer_polygons
from alphafence.geo.outward import simplify_polygon
from alphafence.mavlink.storage import CIRCLE_BYTES, polygon_bytes

PAD_M = 0.05  # onboard fences stand this far outside what they must contain (1e-7 deg < 1.2 cm)
# vertex counts tried per fence (69 and 83 fill a Copter's and a Plane's storage alone)
K_CANDIDATES = (
    tuple(range(4, 13))
    + (14, 16, 18, 20)
    + tuple(range(24, 65, 4))
    + (69, 76, 83, 96, 128, 160, 192, 224, 255)
)


@dataclass
class Option:
    """One way to store a fence onboard.

    Attributes
    ----------
    kind : str
        ``"circle"`` or ``"polygon"``.
    items : int
        Fence items it takes (a polygon: one a vertex).
    bytes : int
        Bytes of fence storage it takes.
    loss : float
        Square metres added (keep-out) or removed (keep-in) relative to the fence.
    local : shapely.Polygon
        The stored shape, metric (a circumscribed polygon for a circle).
    circle : tuple, optional
        ``(x, y, r)`` in metres, for a circle.
    own : bool
        The fence's own vertices, where its reading has more along bowed edges
        (:func:`own_option`).
    """

    kind: str  # "circle" | "polygon"
    items: int
    bytes: int
    loss: float  # m² added (keep-out) or removed (keep-in) relative to the fence
    local: object  # metric polygon (a circumscribed polygon for circles)
    circle: tuple | None = None  # (x, y, r) metric
    own: bool = False  # the fence's own vertices (own_option), where its reading has more

    @property
    def label(self):
        """``"circle"`` or ``"<k>-gon"``, for tables."""
        return "circle" if self.kind == "circle" else f"{self.items}-gon"


@dataclass
class Piece:
    """A polygon to store onboard (one fence, part of one, or several merged) and its options.

    Attributes
    ----------
    sources : list of str
        The site ids it stands for.
    inclusion : bool
        Keep-in (inclusion) rather than keep-out.
    local : shapely.Polygon
        What the onboard item(s) must contain (or stay inside), metric.
    options : list of Option
        Cheapest first, each losing less area than the cheaper ones.
    choice : int
        Index of the chosen option.
    merged : bool
        Made by merging pieces to fit the storage.
    outward : bool, optional
        Simplified outward; None means outward for keep-out and inward for keep-in.
    required : shapely geometry, optional
        What the fences it stands for cover, metric, when that is less than ``local`` (a
        merge: the union of the merged fences, so that its options' loss counts the gaps the
        merged shape fills); None means ``local``.
    """

    sources: list
    inclusion: bool
    local: object  # the metric polygon the onboard item(s) must contain (or stay inside)
    options: list
    choice: int = 0
    merged: bool = False
    outward: bool | None = None  # None: outward for keep-out, inward for keep-in
    required: object = None  # the merged fences' union (None: local)

    @property
    def grows(self) -> bool:
        """Whether the stored shape must contain ``local`` (else it must lie inside it)."""
        return (not self.inclusion) if self.outward is None else self.outward

    @property
    def chosen(self) -> Option:
        """The chosen option."""
        return self.options[self.choice]


def _pareto(options):
    """Options by increasing cost, each strictly better (less loss) than the cheaper ones."""
    options.sort(key=lambda o: (o.items, o.bytes, o.loss))
    out = []
    for o in options:
        if not out or o.loss < out[-1].loss - 1e-9:
            out.append(o)
    return out


EXACT_MITRE_LIMIT = 100.0  # a spike's corner may reach this many pads out to keep its vertex


def _vertices(poly) -> int:
    return len(poly.exterior.coords) - 1


def _offset(poly, pad, mitre_limit):
    """``poly`` moved ``pad`` metres out (in, when negative) with mitred corners, its largest
    part; None when nothing is left. A spike too sharp for ``mitre_limit`` is bevelled (one
    vertex more) unless a mitre of up to :data:`EXACT_MITRE_LIMIT` pads keeps the fence's own
    vertex count."""
    found = None
    for limit in (mitre_limit, EXACT_MITRE_LIMIT):
        parts = outer_polygons(shapely.buffer(poly, pad, join_style="mitre", mitre_limit=limit))
        if not len(parts):
            return found
        part = parts[int(np.argmax(shapely.area(parts)))]
        if found is None or (part.is_valid and _vertices(part) < _vertices(found)):
            found = part
        if _vertices(found) <= _vertices(poly):
            break
    return _keep_clear(found, poly, pad)


def _keep_clear(found, poly, pad):
    """``found`` (``poly`` offset by ``pad``), made to stand at least 0.9 pad clear of
    ``poly``'s boundary everywhere: GEOS bevels a spike too sharp for the mitre limit
    through its very tip, leaving the tip on the offset's boundary, where rounding to 1e-7
    degrees can cut it off. There a round offset (8 segments a circle: 0.92 pad at the
    chords) is joined in."""
    if found is None or shapely.distance(found.exterior, poly.exterior) >= 0.9 * abs(pad):
        return found
    rounded = shapely.buffer(poly, pad, quad_segs=2)
    joined = shapely.union(found, rounded) if pad > 0 else shapely.intersection(found, rounded)
    parts = outer_polygons(joined)
    return parts[int(np.argmax(shapely.area(parts)))] if len(parts) else None


def own_option(own, poly, inclusion: bool, max_vertices: int):
    """The fence stored as its own vertices, ``PAD_M`` out (in, for keep-in), where its
    reading (``poly``) has more: a fence whose lon/lat edges bow in metres is read with
    vertices along each bow, but its own vertices, written back, draw those very edges.
    None when it has no fewer vertices than ``poly`` or more than ``max_vertices``. Whether
    the option, held as read, contains the fence is for the caller to check.

    Parameters
    ----------
    own : shapely.Polygon
        The fence's own vertices in metres, joined by metric chords.
    poly : shapely.Polygon
        The fence as read (its edges followed in lon/lat), metric.
    inclusion : bool
        Keep-in (moved inward) rather than keep-out.
    max_vertices : int
        Most vertices of one polygon the vehicle accepts.

    Returns
    -------
    Option or None
    """
    if not own.is_valid or _vertices(own) >= _vertices(poly):
        return None
    base = _offset(own, -PAD_M if inclusion else PAD_M, 5.0 if inclusion else 10.0)
    if base is None or not 3 <= _vertices(base) <= max_vertices:
        return None
    v = _vertices(base)
    loss = (poly.area - base.area) if inclusion else (base.area - poly.area)
    return Option("polygon", v, polygon_bytes(v), max(loss, 0.0), base, own=True)


def with_own(options, own):
    """``options`` (:func:`piece_options`'s) with ``own`` (:func:`own_option`'s, or None) as
    the last, least-loss one: the options of more vertices than the fence's own approximate
    its reading along the bows, which its own vertices draw exactly (their metric losses
    differ from its by the bows, not by what is fenced)."""
    if own is None:
        return options
    return _pareto([o for o in options if o.items < own.items] + [own])


def piece_options(poly, inclusion: bool, max_vertices: int, circle=None):
    """The ways one fence polygon can be stored, cheapest first.

    A keep-out fence may be a circle (its own, grown by ``PAD_M``, or the enclosing one) or a
    polygon simplified outward; a keep-in fence only a polygon simplified inward. Options that
    cost more without losing less area are left out. The last, least-loss option is the
    fence itself, every vertex ``PAD_M`` out (in, for keep-in) so that rounding to 1e-7
    degrees cannot cut in: it loses only that strip, when the fence has at most
    ``max_vertices`` vertices; a larger fence's last option is its outward (inward)
    simplification to ``max_vertices``.

    Parameters
    ----------
    poly : shapely.Polygon
        The fence, metric.
    inclusion : bool
        Keep-in (simplify inward, no circle) rather than keep-out.
    max_vertices : int
        Most vertices of one polygon the vehicle accepts.
    circle : tuple, optional
        ``(x, y, r)`` of a circle fence, metric.

    Returns
    -------
    list of Option

    Examples
    --------
    >>> import shapely
    >>> opts = piece_options(shapely.box(0, 0, 100, 50), False, 255)
    >>> [o.label for o in opts]
    ['circle', '4-gon']
    >>> opts[1].bytes, round(opts[1].loss, 1)
    (34, 15.0)
    """
    if inclusion:
        base = _offset(poly, -PAD_M, 5.0)
        base = poly if base is None else base
    else:
        base = _offset(poly, PAD_M, 10.0)
    area = poly.area
    opts = []
    if not inclusion:
        c = circle if circle is not None else enclosing_circle(base)
        c = (c[0], c[1], c[2] + PAD_M) if circle is not None else c
        opts.append(
            Option("circle", 1, CIRCLE_BYTES, math.pi * c[2] ** 2 - area, circle_polygon(*c), c)
        )
    n = len(base.exterior.coords) - 1
    ks = sorted({k for k in K_CANDIDATES if k < n} | ({n} if n <= max_vertices else set()))
    for k in ks:
        if k > max_vertices:
            break
        simp = simplify_polygon(base, k, 0.0, outward=not inclusion) if k < n else base
        v = len(simp.exterior.coords) - 1
        if v > max_vertices or v < 3:
            continue
        loss = (area - simp.area) if inclusion else (simp.area - area)
        opts.append(Option("polygon", v, polygon_bytes(v), max(loss, 0.0), simp))
    return _pareto(opts)
