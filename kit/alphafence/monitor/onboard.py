"""The fence the vehicle itself enforces, as a layer of the monitor's own.

ArduPilot enforces the fence it holds, not the full-resolution fences: a compiled onboard fence
is larger (circles and coarse polygons that contain the real fences), so the vehicle can breach
it well before any real fence. The monitor downloads that fence (the runner does the I/O) and
checks and predicts against it beside the full-resolution fences, with the same assessment
(distance, time to breach, stopping distance). Exclusions are keep-out fences; an inclusion is
a keep-in fence (outside it: a breach) plus, for the prediction, a keep-out band around it, so
that leaving it is predicted like entering a keep-out fence.

Pure: :class:`OnboardLayer` is built from fence items in the monitor's metric frame, and
:meth:`OnboardLayer.decide` picks which layer an alert is about.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import shapely

from alphafence.awareness.fenceset import FenceSet
from alphafence.awareness.state import Assessment, Level, assess
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.monitor.events import new_event
from alphafence.onboard.decode import breached, decode_fence

OUTSIDE_BAND_M = 20_000.0  # how far beyond an inclusion its keep-out band reaches
SAME_FENCE_M = 2.0  # an onboard fence this close to a real one is that fence (rounding, arcs)
ONLY_WORDS = "onboard fence only: the full-resolution fences allow this airspace"


class OnboardLayer:
    """A vehicle's fence, indexed in the monitor's frame.

    Parameters
    ----------
    fences : list of OnboardFence
        The decoded fence (``alphafence.onboard.decode``).
    frame : LocalFrame
        The monitor's metric frame (the full-resolution fences').
    items : int
        How many items the fence had (the return point included).
    union : bool
        Whether the vehicle reads its inclusions as their union (``FENCE_OPTIONS`` bit 1,
        :mod:`alphafence.mavlink.inclusions`) or, ArduPilot's default, their intersection:
        outside any one of them is then a breach.

    Attributes
    ----------
    fences : list of OnboardFence
        Those with an area (a polygon whose vertices lie on a line bounds nothing: ``empty``).
    index : FenceSet or None
        None when no fence has an area.
    """

    def __init__(self, fences, frame, items: int, union: bool = False):
        self.items = items
        self.union = union
        shapes = [(f, f.geometry()) for f in fences]
        self.fences = [f for f, g in shapes if not g.is_empty]
        self.empty = [f for f, g in shapes if g.is_empty]
        self.frame = frame
        inclusions = [frame.read_geom(g) for f, g in shapes if f.inclusion and not g.is_empty]
        # under the union, leaving one inclusion for another is no breach: each band leaves
        # out every inclusion
        allowed = shapely.union_all(inclusions) if union and len(inclusions) > 1 else None
        records, self._owner = [], []
        for k, (f, geometry) in enumerate((f, g) for f, g in shapes if not g.is_empty):
            if f.inclusion:
                records.append(FenceRecord(f.name, "keep_in", geometry))
                self._owner.append(k)
                geometry = _outside_band(geometry, frame, allowed)
            records.append(FenceRecord(f.name, "keep_out", geometry))
            self._owner.append(k)
        self.index = FenceSet(records, frame=frame, keep_in_union=union) if records else None

    @classmethod
    def from_items(cls, items, frame, source: str = "the vehicle's fence", union: bool = False):
        """Decode ``items`` (raising InputError for a malformed fence) and index them, the
        inclusions read by the vehicle's rule (``union``: ``FENCE_OPTIONS`` bit 1)."""
        items = list(items)
        return cls(decode_fence(items, source), frame, len(items), union)

    def breached(self, lon, lat) -> bool:
        """Whether the vehicle breaches this fence at ``(lon, lat)`` by its own rule
        (:func:`alphafence.onboard.decode.breached`: polygons on its integer degrees, circles
        by its distance, inclusions by :attr:`union`)."""
        return breached(self.fences, lon, lat, self.union)

    @property
    def counts(self) -> dict:
        """``{"exclusion polygon": n, ...}``: how many fences of each kind and shape."""
        out = {}
        for f in self.fences:
            key = f"{f.kind} {f.shape}"
            out[key] = out.get(key, 0) + 1
        return out

    def fence(self, record) -> object:
        """The OnboardFence behind the index's record number ``record``."""
        return self.fences[self._owner[record]]

    def decide(self, full: Assessment, fences: FenceSet, x, y, alt, ve, vn, lookahead_m, options):
        """The worse of the full-resolution fences' level (``full``) and this layer's, and
        which layer it is about; the full-resolution fences name a tie.

        Parameters
        ----------
        full : Assessment
            The full-resolution fences' raw level at this position.
        fences : FenceSet
            The full-resolution fences (in this layer's frame).
        x, y : float
            Metres in the frame.
        alt : float
            Metres above home (ArduPilot's polygons and circles hold at every altitude).
        ve, vn : float
            Velocity east and north, m/s.
        lookahead_m : float
            How far ahead along the track to look.
        options : MonitorOptions
            The horizon and the braking model.

        Returns
        -------
        Decision
        """
        if self.index is None:
            return Decision(full, full_level=full.level)
        speed = math.hypot(ve, vn)
        check = self.last_check = self.index.check(x, y, alt, ve, vn, lookahead_m)
        a = assess(check, speed, options.horizon_s, options.braking)
        if a.level <= full.level:
            return Decision(full, full_level=full.level)
        fence = self.fence(a.fence)
        # where the vehicle meets the onboard fence: along the track, or where it is
        px, py = x, y
        if check.breach_ahead == (a.fence, a.distance_m) and speed > 0:
            px, py = x + ve / speed * a.distance_m, y + vn / speed * a.distance_m
        real = fences.near(px, py, alt, SAME_FENCE_M)
        if real is not None:  # the onboard fence is the real fence there (to rounding)
            return Decision(a, fence, False, full.level, fences.records[real].site_id)
        reason = f"{a.reason} ({ONLY_WORDS})"
        a = Assessment(a.level, a.fence, a.distance_m, a.time_to_breach_s, a.stopping_m, reason)
        return Decision(a, fence, True, full.level)

    def forbidden_beyond(self, full: FenceSet) -> float:
        """Square metres the vehicle's exclusions forbid that no full-resolution keep-out
        fence does (around the vehicle's fence only)."""
        exclusions = [
            self.index.local[k]
            for k in range(len(self.index.records))
            if self.index.records[k].kind == "keep_out" and not self.fence(k).inclusion
        ]
        if not exclusions:
            return 0.0
        onboard = shapely.union_all(exclusions)
        if full.frame is not self.frame:  # pragma: no cover - the runner shares the frame
            return float(onboard.area)
        near = full.tree.query(onboard, predicate="intersects")
        keep_out = [full.local[k] for k in near if full.records[k].kind == "keep_out"]
        real = shapely.union_all(keep_out) if keep_out else shapely.Polygon()
        return float(onboard.difference(real).area)


def _outside_band(inclusion, frame, allowed=None):
    """The keep-out band around an inclusion (WGS84): a box reaching ``OUTSIDE_BAND_M`` beyond
    it, minus the inclusion (or minus ``allowed``, the union of every inclusion, in the
    frame's metres)."""
    local = frame.read_geom(inclusion)
    x0, y0, x1, y1 = local.bounds
    d = OUTSIDE_BAND_M
    keep = local if allowed is None else allowed
    return frame.geom_to_wgs84(shapely.box(x0 - d, y0 - d, x1 + d, y1 + d).difference(keep))


@dataclass(frozen=True)
class Decision:
    """Which layer an alert level is about.

    Attributes
    ----------
    assessment : Assessment
        The deciding layer's (its ``fence``: a full-resolution fence index, or the onboard
        layer's record number).
    onboard : OnboardFence or None
        The vehicle's fence item that raised the level, or None (the full-resolution fences
        did).
    onboard_only : bool
        The onboard fence raises a level the full-resolution fences do not, where no
        full-resolution fence is within ``SAME_FENCE_M``: it forbids airspace they allow.
    full_level : Level
        The full-resolution fences' own level.
    site : str or None
        The full-resolution fence the onboard fence coincides with where the vehicle meets
        it (``onboard`` set, ``onboard_only`` False).

    Examples
    --------
    >>> calm = Assessment(Level.CLEAR, None, float("inf"), float("inf"), 2.0, "clear")
    >>> Decision(calm).onboard is None
    True
    """

    assessment: Assessment
    onboard: object = None
    onboard_only: bool = False
    full_level: Level = Level.CLEAR
    site: str | None = None


def load_layer(previous, items, full: FenceSet, t=None, at=None, union=False, **fields):
    """The vehicle's fence items as the new onboard layer, and the event that says so.

    Parameters
    ----------
    previous : OnboardLayer or None
        The layer in use, kept when ``items`` are not a valid fence.
    items : sequence of FenceItem
        The vehicle's fence, in sequence order.
    full : FenceSet
        The full-resolution fences (their frame is the layer's).
    t : float, optional
        When (``time.monotonic()`` seconds).
    at : Sample, optional
        Where the vehicle was.
    union : bool
        The vehicle reads its inclusions as their union (``FENCE_OPTIONS`` bit 1).
    **fields
        More fields for the event (the runner's ``cause``).

    Returns
    -------
    layer : OnboardLayer or None
    events : list of dict
        ``onboard_fence`` (``items``, ``fences`` by kind and shape, ``forbidden_beyond_m2``:
        what the vehicle's exclusions forbid that no full-resolution keep-out does,
        ``inclusions``: ``"union"`` or ``"intersection"``, and a ``warning`` when the vehicle
        reads two or more inclusions as their intersection or its last position breaches the
        fence as the vehicle reads it),
        ``onboard_none`` (the vehicle holds no fence: no layer) or ``onboard_failed`` (not a
        valid fence: the previous layer is kept).
    """
    from alphafence.errors import InputError

    items = list(items)
    try:
        layer = OnboardLayer.from_items(items, full.frame, union=union)
    except InputError as exc:
        return previous, unreadable(previous, str(exc), t, at, **fields)
    if layer.index is None:
        what = "the vehicle holds no fence" if not items else "no item of the fence bounds an area"
        return None, [new_event("onboard_none", t, at, items=len(items), reason=what, **fields)]
    event = new_event(
        "onboard_fence",
        t,
        at,
        items=len(items),
        fences=layer.counts,
        forbidden_beyond_m2=round(layer.forbidden_beyond(full)),
        **fields,
    )
    inclusions = sum(f.inclusion for f in layer.fences)
    if inclusions > 1:
        event["inclusions"] = "union" if union else "intersection"
    warnings = []
    if inclusions > 1 and not union:
        warnings.append(
            f"the vehicle holds {inclusions} inclusions and reads them as their intersection "
            f"(FENCE_OPTIONS bit 1 unset): it must stay inside every one of them"
        )
    if at is not None and layer.breached(at.lon, at.lat):
        warnings.append("the vehicle's last position breaches its fence as the vehicle reads it")
    if warnings:
        event["warning"] = "; ".join(warnings)
    if layer.empty:
        event["without_area"] = [f.name for f in layer.empty]
    return layer, [event]


def unreadable(previous, error, t=None, at=None, **fields) -> list:
    """The ``onboard_failed`` event for a fence that could not be read (the download failed,
    or the items are not a valid fence): the monitor keeps ``previous``."""
    if previous is None:
        kept = "no onboard fence: the full-resolution fences only"
    else:
        kept = f"the previous onboard fence ({previous.items} items)"
    return [new_event("onboard_failed", t, at, error=error, kept=kept, **fields)]


async def download_layer(monitor, cause: str) -> list:
    """:meth:`Monitor.reload_onboard <alphafence.monitor.runner.Monitor.reload_onboard>`:
    download the vehicle's fence, load it into the engine, handle the events."""
    import asyncio
    import time

    from alphafence.errors import VehicleError
    from alphafence.mavlink.inclusions import needs_union
    from alphafence.vehicle.fence_transfer import download_fence
    from alphafence.vehicle.params import vehicle_union

    t0 = time.monotonic()
    try:
        items = await download_fence(monitor.vehicle)
        union = await vehicle_union(monitor.vehicle) if needs_union(items) else False
    except asyncio.CancelledError:
        raise
    except Exception as exc:  # a failed download is an event: the monitor goes on
        error = str(exc) if isinstance(exc, VehicleError) else f"{type(exc).__name__}: {exc}"
        events = monitor.engine.onboard_unreadable(error, cause=cause)
    else:
        seconds = round(time.monotonic() - t0, 3)
        events = monitor.engine.load_onboard(items, cause=cause, seconds=seconds, union=union)
    for event in events:
        monitor.handle(event)
    return events
