"""Compile fences into ArduPilot's small fence storage.

ArduPilot keeps fences in a few hundred bytes (Copter: 560 bytes, at most 70 items): a
polygon costs 2 + 8 bytes a vertex (one item a vertex), a circle 13 bytes (one item), the
return point 9, plus a 4-byte header and a 1-byte end marker. The compiler picks the fences
within the selection distance of the flight path (or of an operating box): the *corridor*
(``onboard.corridor``), and chooses, per fence, a circle or a polygon of k vertices, each
simplified *outward* (keep-out) or *inward* (keep-in) so the onboard fence still contains
(or stays inside) the fence it stands for, to lose the least airspace in the corridor within
the budget (``onboard.options``). When even the cheapest choice does not fit, neighbouring
fences are merged, those whose merge costs least in the corridor first (an alpha shape of
the two; ``onboard.merge``). Coordinates are rounded to MAVLink's 1e-7 degrees, and every
emitted polygon is re-checked after rounding (``onboard.emit``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import shapely

from alphafence.errors import InputError
from alphafence.geo.alpha import outer_polygons
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.autopilots import inclusion_union_possible
from alphafence.mavlink.items import RETURN_POINT, FenceItem
from alphafence.mavlink.storage import END_BYTES, HEADER_BYTES, RETURN_BYTES, Profile, storage_bytes
from alphafence.onboard.clear import check_held
from alphafence.onboard.corridor import Corridor, LossModel, Overshoot, overshoot
from alphafence.onboard.emit import emit_items, own_held
from alphafence.onboard.gaps import gap_pieces
from alphafence.onboard.merge import fit_by_merging, merge_to_upgrade, upgrade
from alphafence.onboard.options import Piece, piece_options, with_own
from alphafence.onboard.rules import check_for_autopilot


@dataclass
class CompileResult:
    """What :func:`compile_fences` made.

    Attributes
    ----------
    items : list of FenceItem
        The onboard fence, in upload order.
    pieces : list of Piece
        What each item or group of items stands for, with the option chosen.
    profile : Profile
        The storage compiled for (``--items`` applied).
    frame : LocalFrame
        The metric frame of the pieces.
    dropped : list of str
        Site ids of fences farther from the area than the selection distance.
    merges : list of tuple
        The site ids of each merge made to fit the storage.
    return_point : tuple, optional
        ``(lon, lat)`` of the return point.
    corridor : Corridor, optional
        Where the vehicle flies (metric): the flight path or box, and the selection distance.
    overshoot : Overshoot, optional
        The onboard fence's overshoot within the corridor: airspace it forbids there that
        the full-resolution fences allow, relative to what they forbid there.
    names : dict
        Site id -> the site's name, for the compiled fences that have one.
    """

    items: list
    pieces: list
    profile: Profile
    frame: LocalFrame
    dropped: list = field(default_factory=list)  # fences far from the area (not compiled)
    merges: list = field(default_factory=list)  # [(sources...)] merged to fit
    return_point: tuple | None = None
    corridor: Corridor | None = None
    overshoot: Overshoot | None = None
    names: dict = field(default_factory=dict)

    def label(self, site_id: str) -> str:
        """A site as tables name it: ``"hospital/way/1 (St Mary's)"``, or its id alone."""
        name = self.names.get(site_id)
        return f"{site_id} ({name})" if name else site_id

    def fence_sites(self) -> list:
        """The sites each polygon and circle of :attr:`items` stands for (``{"id", "name"}``
        each), in the order :func:`~alphafence.onboard.decode.decode_fence` reads them (a
        plan's polygons, then its circles): those of the piece it overlaps most (a piece
        split at 180° stands behind each of its parts)."""
        from alphafence.onboard.decode import decode_fence

        chosen = [p.chosen.local for p in self.pieces]
        out = []
        for f in decode_fence(self.items):
            xy = [tuple(self.frame.to_local(lon, lat)) for lon, lat in f.lonlat]
            shape = (
                shapely.Polygon(xy)
                if f.shape == "polygon"
                else shapely.Point(xy[0]).buffer(f.radius_m)
            )
            shape = shapely.make_valid(shape)
            overlap = [shapely.area(shapely.intersection(shape, g)) for g in chosen]
            k = max(range(len(chosen)), key=overlap.__getitem__, default=None)
            ids = self.pieces[k].sources if k is not None and overlap[k] > 0 else []
            out.append([{"id": i, "name": self.names.get(i)} for i in ids])
        return out

    @property
    def bytes_used(self) -> int:
        """Bytes of fence storage the items take."""
        return storage_bytes(self.items)

    @property
    def loss_m2(self) -> float:
        """Square metres the onboard fence adds (keep-out) or gives up (keep-in), piece by
        piece, as the compiler counts them: in the corridor (area outside it counts
        ``corridor.LOSS_OUTSIDE`` as much)."""
        return sum(p.chosen.loss for p in self.pieces)


def _label(rec) -> str:
    return f"{rec.site_id} ({rec.name})" if rec.name else rec.site_id


def operating_area_from_plan(path):
    """The convex hull of a mission's positions and its first position (what the compiler
    selected fences around before it followed the flight path,
    :func:`alphafence.onboard.corridor.flight_path_from_plan`).

    Parameters
    ----------
    path : str or Path
        A QGroundControl ``.plan`` or a QGC WPL waypoint file.

    Returns
    -------
    area : shapely geometry
        The convex hull of the positions the mission flies through, home included (WGS84).
    first : tuple
        ``(lon, lat)`` of its first position.
    """
    from alphafence.flights.mission import read_mission

    pts = [(w.lon, w.lat) for w in read_mission(path, min_positions=1)]
    return shapely.MultiPoint(pts).convex_hull, pts[0]


def compile_fences(
    records,
    area,
    profile: Profile,
    distance_m=2000.0,
    keep_in_m=None,
    return_point=None,
    max_items=None,
    keep_clear=None,
    inclusions=None,
) -> CompileResult:
    """Fit the fences near a flight path (or an operating area) into a vehicle's fence storage.

    Warning layers are left to the companion; keep-out and keep-in fences within
    ``distance_m`` of ``area`` (they reach into the corridor) are each stored as the option
    that loses the least airspace in the corridor within the budget, merging neighbouring
    keep-out fences when they do not fit otherwise.

    Parameters
    ----------
    records : list of FenceRecord
        The fences, as ``read_fences`` returns them.
    area : shapely geometry
        Where the vehicle flies (WGS84 lon, lat): a flight path (LineString or Point, e.g.
        :func:`~alphafence.onboard.corridor.flight_path_from_plan`) or an area (Polygon).
    profile : Profile
        The vehicle's fence storage, and the autopilot whose rules the items follow
        (``profile.autopilot``: circle radii by its distance; for PX4 no return point and at
        most one inclusion, :func:`~alphafence.onboard.rules.check_for_autopilot`).
    distance_m : float
        Fences farther than this from ``area`` are left out; within it lies the corridor.
    keep_in_m : float, optional
        Also store an inclusion fence this many metres around ``area`` (kept generous:
        simplified outward, at most 8 vertices where that loses nothing).
    return_point : tuple, optional
        ``(lon, lat)`` of the fence's return point.
    max_items : int, optional
        At most this many items (within the profile).
    keep_clear : KeepClear, optional
        Home (and the vehicle's position): no item chosen covers them or comes within the
        clearance of them (:mod:`alphafence.onboard.clear`); a fence that itself holds one is
        refused by name.
    inclusions : str, optional
        How the vehicle reads several inclusions: ``"union"`` (ArduPilot with FENCE_OPTIONS
        bit 1) or ``"intersection"`` (PX4, older ArduPilot); by default the autopilot's
        (:func:`~alphafence.mavlink.autopilots.inclusion_union_possible`). Under the
        intersection, two or more keep-in areas are stored as one inclusion round them and
        an exclusion for each gap (:mod:`alphafence.onboard.gaps`).

    Returns
    -------
    CompileResult

    Raises
    ------
    InputError
        When the fences near the area cannot fit even merged, or a fence holds a point of
        ``keep_clear``.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> from alphafence.mavlink.storage import PROFILES
    >>> square = shapely.box(14.500, 35.900, 14.501, 35.901)
    >>> fence = FenceRecord("hospital/way/1", "keep_out", square)
    >>> path = shapely.LineString([(14.49, 35.9), (14.51, 35.9)])
    >>> result = compile_fences([fence], path, PROFILES["copter"])
    >>> len(result.items), result.bytes_used, result.pieces[0].chosen.label
    (4, 39, '4-gon')
    >>> round(result.overshoot.ratio, 3)  # the 5 cm pad, and a square is no rectangle in metres
    0.002
    """
    if return_point is not None:
        check_for_autopilot([FenceItem(RETURN_POINT, 0.0, *return_point)], profile.autopilot)
    frame = LocalFrame.around(area)
    area_local = frame.read_geom(area)
    corridor = Corridor.around(area_local, distance_m)
    if max_items is not None:
        profile = dataclasses.replace(profile, items=min(profile.items, max_items))
    clear = keep_clear.local(frame) if keep_clear is not None else None
    pieces, dropped, full, kept_in = [], [], ([], []), []
    for rec in records:
        if rec.kind not in ("keep_out", "keep_in"):
            continue
        local = frame.read_geom(rec.geometry)  # its edges straight in lon/lat, as written
        if not local.is_valid or shapely.get_type_id(local) == 7:
            # a ring that projects to a self-touching one, or repaired into polygons and the
            # spikes it drew out and back: keep all of it, spikes included
            local = shapely.buffer(shapely.make_valid(local), 1e-3, join_style="mitre")
        if shapely.distance(local, area_local) > distance_m:
            dropped.append(rec.site_id)
            continue
        full[rec.kind == "keep_in"].append(local)
        if clear is not None:  # a fence over home is the fence's, not the compiler's
            clear.check_zone("compile", _label(rec), local, rec.kind == "keep_in")
            if rec.kind == "keep_in":
                kept_in.append((_label(rec), local))
        circle = None
        if rec.circle is not None:
            x, y = frame.to_local(rec.circle[0], rec.circle[1])
            circle = (float(x), float(y), rec.circle[2])
        parts = outer_polygons(local)
        for part in parts:
            opts = piece_options(part, rec.kind == "keep_in", profile.max_polygon_vertices, circle)
            if len(parts) == 1:
                opts = with_own(opts, own_held(rec, part, frame, profile.max_polygon_vertices))
            if opts:
                pieces.append(Piece([rec.site_id], rec.kind == "keep_in", part, opts))
    if inclusions is None:
        inclusions = "union" if inclusion_union_possible(profile.autopilot) else "intersection"
    if inclusions == "intersection" and sum(p.inclusion for p in pieces) > 1:
        hull, gaps, _ = gap_pieces(
            [p for p in pieces if p.inclusion], profile.max_polygon_vertices, frame
        )
        pieces = [hull, *(p for p in pieces if not p.inclusion), *gaps]
        full[0].extend(g.local for g in gaps)  # forbidden: no keep-in area allows them
    model = LossModel(corridor, full[0], clear)
    for p in pieces:
        if not model.rescore(p):
            raise InputError(
                "compile",
                f"{', '.join(p.sources)}: no shape the vehicle can hold leaves "
                f"{clear.keep.points[0].label} {clear.keep.clearance_m:g} m clear; compile with "
                "a smaller --home-clearance",
            )
    fixed_items, fixed_bytes = 0, HEADER_BYTES + END_BYTES
    if return_point is not None:
        fixed_items += 1
        fixed_bytes += RETURN_BYTES
    if keep_in_m is not None:
        allowed = outer_polygons(shapely.buffer(area_local, keep_in_m))[0]
        # the operator's area: stored generously (outward), never inside what they asked for
        opts = [
            o
            for o in piece_options(allowed, False, profile.max_polygon_vertices)
            if o.kind == "polygon"
        ]
        keep = Piece(
            ["operating-area"],
            True,
            allowed,
            [min(opts, key=lambda o: (o.items > 8, o.loss))],
            outward=True,
        )
        keep.options[0].loss = 0.0
        pieces.insert(0, keep)
        kept_in.insert(0, ("the --keep-in area", allowed))
    if clear is not None:
        clear.check_keep_in("compile", kept_in)
    budget_items = profile.items - fixed_items
    budget_bytes = profile.bytes - fixed_bytes
    merges = []
    spare = 0
    for _ in range(8):  # held as read, a bowed edge or a part across 180° may take more items
        fit_by_merging(pieces, budget_items, budget_bytes, profile, merges, model)
        upgrade(pieces, budget_items, budget_bytes)
        merge_to_upgrade(pieces, budget_items, budget_bytes, profile, merges, model=model)
        try:
            items = emit_items(pieces, frame, return_point, profile.autopilot)
        except InputError:  # a shape that cannot be held as read: choose again without it
            items = None
            if not _count_as_emitted(pieces, frame):
                raise
            for p in pieces:
                p.choice = 0
            continue
        over_items = len(items) - profile.items
        over_bytes = storage_bytes(items) - profile.bytes
        if over_items <= 0 and over_bytes <= 0:
            break
        if not _count_as_emitted(pieces, frame):  # else the options now cost what they take
            spare = max(2 * spare, over_items, -(-over_bytes // 8), 1)  # vertices to leave free
            budget_items -= spare
            budget_bytes -= 8 * spare
        for p in pieces:
            p.choice = 0
    if items is None:  # the last choice could not be held either: said as emit says it
        items = emit_items(pieces, frame, return_point, profile.autopilot)
    onboard = tuple(
        [p.chosen.local for p in pieces if p.inclusion == kind and not (kind and p.grows)]
        for kind in (False, True)
    )
    result = CompileResult(
        items,
        pieces,
        profile,
        frame,
        dropped,
        merges,
        return_point,
        corridor,
        overshoot(corridor, onboard, full),
        {r.site_id: r.name for r in records if r.name and r.kind in ("keep_out", "keep_in")},
    )
    check_for_autopilot(items, profile.autopilot)  # PX4: one inclusion at most
    check_held(items, clear, inclusions == "union")  # home clear as the vehicle reads the items
    used = storage_bytes(items)
    if len(items) > profile.items or used > profile.bytes:  # a fence split at 180° grew
        raise InputError(
            "compile",
            f"the fences near the area do not fit a {profile.name} as the autopilot reads them "
            f"({len(items)} items / {used} bytes: edges held as read, parts on each side of "
            "180°); narrow the operating area",
        )
    return result


UNHELD = 1 << 30  # the cost of a shape that cannot be held as read: more than any storage


def _count_as_emitted(pieces, frame) -> bool:
    """Give the options of each piece whose choice took more when emitted, held as ArduPilot
    reads it (a long edge bowed in lon/lat takes more vertices than the option counted), the
    items and bytes each takes, so the next choice sees what they cost. Whether any rose."""
    rose = False
    for p in pieces:
        if _emitted_cost(p, frame):
            rose = True
            chosen = p.choice
            for k in range(len(p.options)):  # its other shapes bow alike
                p.choice = k
                _emitted_cost(p, frame)
            p.choice = chosen
    return rose


def _emitted_cost(piece, frame) -> bool:
    """Raise the chosen option's cost to what it takes emitted (past any storage when it
    cannot be held as read); whether it rose."""
    try:
        own = emit_items([piece], frame)
        n, nbytes = len(own), storage_bytes(own) - HEADER_BYTES - END_BYTES
    except (InputError, shapely.errors.GEOSException):  # rounded, its reading would not hold
        # (or not even split at 180°): never chosen again
        n = nbytes = UNHELD
    o = piece.chosen
    if n <= o.items and nbytes <= o.bytes:
        return False
    o.items, o.bytes = max(n, o.items), max(nbytes, o.bytes)
    return True
