"""Which of a live source's zones are in force: nothing is lost when the source misbehaves.

Pure (no I/O): :class:`LiveZones` takes each answer of the source and says what changed.

* A zone is added (or a new version of it) by any answer, complete or not: more restriction
  is never unsafe.
* A zone is removed only by a **complete** answer (every page read) for an area that its
  geometry meets and that no longer holds it; an answer for another area says nothing of it.
  A changed zone's old version goes the same way, when a complete answer holds the new one.
* A failed or incomplete answer removes nothing.
* A zone in force that an answer serves malformed (a feature that is not a zone, or cannot be
  fenced: ``held``) is kept as it was, and said to be; only a complete answer without it at
  all removes it.
* A complete answer that is empty where zones were in force in its area is reported and
  removes nothing; only a second such answer in a row removes them.
* Time windows are the fences' own (``properties["zone"]["applicability"]``): the monitor's
  fence set switches them; :func:`window_state` says when one starts and ends.

So the zones in force always hold the last complete answer's, and everything in force before
it that no complete answer for its area has dropped (``tests/test_live_zones.py`` proves it
for any sequence of answers).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import shapely


@dataclass
class Change:
    """What one answer changed.

    Attributes
    ----------
    added, changed, removed : list of Zone
        New zones, new versions of zones in force (the new version), zones no longer in force.
    kept_empty : list of Zone
        Zones an empty answer would have removed, kept until a second one confirms it.
    held : list of Zone
        Zones in force that the answer served malformed: kept as they were.
    """

    added: list = field(default_factory=list)
    held: list = field(default_factory=list)
    changed: list = field(default_factory=list)
    removed: list = field(default_factory=list)
    kept_empty: list = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.added or self.changed or self.removed)


def zone_meets(zone, box) -> bool:
    """Whether ``zone``'s geometry meets the lon/lat ``box`` (its restricted features', else
    its feature's; a zone without a readable geometry meets every box)."""
    geoms = [f.geometry for f in zone.restricted]
    if not geoms and isinstance((zone.feature or {}).get("geometry"), dict):
        with contextlib.suppress(Exception):  # a geometry GEOS cannot read meets every box
            geoms = [shapely.geometry.shape(zone.feature["geometry"])]
    if box is None or not geoms:
        return True
    area = shapely.box(*box)
    return any(shapely.intersects(g, area) for g in geoms)


class LiveZones:
    """The zones of one source in force, version by version.

    Attributes
    ----------
    versions : dict
        ``{(zone id, hash): Zone}`` in force (a zone's old version stays beside the new one
        until a complete answer drops it).
    empty_pending : bool
        The last complete answer was empty where zones were: the next empty one removes them.
    revision : int
        Counts the answers that changed what is in force.
    """

    def __init__(self, zones=()):
        self.versions = {(z.id, z.hash): z for z in zones}
        self.empty_pending = False
        self.revision = 0  # one more at every answer that changed what is in force

    @property
    def zones(self) -> list:
        """The zones in force (every version), in the order they came."""
        return list(self.versions.values())

    def answer(self, zones, complete: bool, bbox=None, held=()) -> Change:
        """Take one answer.

        Parameters
        ----------
        zones : list of Zone
            The zones it holds (for an answer whose pages failed part way, those read).
        complete : bool
            Every page was read.
        bbox : tuple, optional
            The area it was asked for (lon, lat); None: everything.
        held : iterable of str
            Ids of the zones it served malformed: what is in force of them is kept.

        Returns
        -------
        Change
        """
        change = self._answer(zones, complete, bbox, set(held))
        self.revision += bool(change)
        return change

    def _answer(self, zones, complete, bbox, held) -> Change:
        change = Change()
        change.held = [z for k, z in self.versions.items() if k[0] in held]
        ids_in_force = {k[0] for k in self.versions}
        served = {(z.id, z.hash) for z in zones}
        for z in zones:
            key = (z.id, z.hash)
            if key in self.versions:
                continue
            (change.changed if z.id in ids_in_force else change.added).append(z)
            self.versions[key] = z
        if not complete:
            return change
        gone = [k for k, z in self.versions.items()
                if k not in served and k[0] not in held and zone_meets(z, bbox)]  # fmt: skip
        if not zones and gone:
            if not self.empty_pending:
                self.empty_pending = True
                change.kept_empty = [self.versions[k] for k in gone]
                return change
        self.empty_pending = False
        still = {z.id for z in zones}
        for k in gone:
            z = self.versions.pop(k)
            if z.id not in still:  # an old version of a zone still served is no removal
                change.removed.append(z)
        return change


def window_state(applicability, when, announce_s: float = 600.0, slack_s: float = 0.0) -> str:
    """Where a zone's time window stands at ``when`` (an aware datetime): ``"always"``,
    ``"active"``, ``"upcoming"`` (it starts within ``announce_s``), ``"ended"`` (no start
    after ``when``) or ``"later"``. With ``slack_s`` (this clock's doubt), a zone active
    anywhere within ``when`` ± ``slack_s`` is active.

    Examples
    --------
    >>> from datetime import datetime, timezone
    >>> now = datetime(2026, 12, 6, 12, 0, tzinfo=timezone.utc)
    >>> w = [{"startDateTime": "2026-12-06T12:05:00Z", "endDateTime": "2026-12-06T13:00:00Z"}]
    >>> window_state(w, now), window_state(w, now, slack_s=600), window_state(None, now)
    ('upcoming', 'active', 'always')
    >>> window_state([{"endDateTime": "2026-12-06T11:00:00Z"}], now)
    'ended'
    """
    from datetime import timedelta

    from alphafence.awareness.applicability import active_within, is_active, timed

    if not timed(applicability):
        return "always"
    if active_within(applicability, when, slack_s):
        return "active"
    steps = max(1, int(announce_s // 30))
    if any(is_active(applicability, when + timedelta(seconds=announce_s * k / steps))
           for k in range(1, steps + 1)):  # fmt: skip
        return "upcoming"
    entries = applicability if isinstance(applicability, list) else [applicability]
    ends = [_end(e) for e in entries]
    if ends and all(end is not None and end < when for end in ends):
        return "ended"
    return "later"


def _end(entry):
    from alphafence.awareness.applicability import _dt

    return _dt(entry.get("endDateTime")) if isinstance(entry, dict) else None


def copied_zones(records, fenced) -> list:
    """The offline copy's zones, one per ``(source_zone, source_hash)`` of its fences; each
    version's fence records go into ``fenced`` (``{hash: [FenceRecord]}``)."""
    import shapely

    from alphafence.sources.answers import Zone

    groups = {}
    for r in records:
        key = (str(r.properties["source_zone"]), str(r.properties["source_hash"]))
        groups.setdefault(key, []).append(r)
    zones = []
    for (zid, digest), recs in groups.items():
        fenced[digest] = recs
        window = ((recs[0].properties or {}).get("zone") or {}).get("applicability")
        outline = shapely.union_all([r.geometry for r in recs])
        feature = {"type": "Feature", "id": zid, "properties": {},
                   "geometry": shapely.geometry.mapping(outline)}  # fmt: skip
        zones.append(Zone(zid, digest, feature, (), window))
    return zones


def split_copy(records):
    """``(base, copied)``: the fences not from a source, and those from one (an offline copy's,
    with ``source_zone`` and ``source_hash``)."""
    copied = [r for r in records if "source_zone" in (r.properties or {})]
    base = [r for r in records if "source_zone" not in (r.properties or {})]
    return base, copied
