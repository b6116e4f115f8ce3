"""The post-flight check: did a flight enter a restricted zone?

Every position of a flight log (:mod:`alphafence.flights.flight_log`) goes through the monitor's
own fence index and engine (:class:`~alphafence.awareness.fenceset.FenceSet`,
:class:`~alphafence.monitor.engine.Engine`) at the log's own times: time windows (ED-269
applicability) are those in force when it flew, and altitude limits are compared with the log's
altitude in each limit's reference (AMSL limits with the altitude AMSL, AGL ones and limits
without a reference with the height above home, as the monitor does). What comes out, per fence:

* **incursions**: a keep-out fence (in force, within its altitude band) entered, a keep-in fence
  left, a warning layer entered: from the first position inside to the first outside again,
  with the deepest point; also those that happen *between* two positions (the straight line
  between them crosses a keep-out fence, or leaves a keep-in fence), which no sample shows;
* **closest approach** (horizontal) of the track, the straight lines between positions, to every
  fence within ``near_m``: where and when, the altitude then, and whether it was in force;
* **alerts**: the monitor's own rising alert levels (WARNING, IMMINENT, BREACH) and GPS glitches,
  as its engine would have raised them in flight.

The flight *entered* a zone (:attr:`FlightReport.entered`) when it entered a keep-out fence in
force or left a keep-in fence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np

from alphafence.awareness.fenceset import FenceSet, reference
from alphafence.errors import InputError
from alphafence.monitor.engine import Engine
from alphafence.monitor.events import utc_text
from alphafence.monitor.options import MonitorOptions
from alphafence.review.postflight_track import Walker

NEAR_M = 500.0  # fences this close to the track get a closest approach


def load_fences(path) -> FenceSet:
    """The fences of any fence file (``read_fence_file``), indexed; InputError if none."""
    from alphafence.fencefiles.fence_read import read_fence_file

    records = read_fence_file(path)
    if not records:
        raise InputError(path, "holds no fences: nothing to check the flight against")
    return FenceSet(records)


@dataclass
class FlightReport:
    """What a flight did near the fences (see the module).

    Attributes
    ----------
    info : LogInfo
        The log, as read.
    fences : FenceSet
    near_m : float
    incursions : list of Incursion
        In time order.
    closest : dict
        Fence index -> :class:`Approach`, for fences within ``near_m`` of the track.
    alerts : list of dict
        The engine's rising levels and GPS glitches (events; ``time`` as in the log).
    in_force : dict
        Fence index -> ``"yes"``, ``"no"`` or ``"partly"`` during the flight.
    start_t, end_t : float
    track : numpy.ndarray
        ``(n, 5)``: t, lon, lat, height above home, and 1 where the position was in a breach
        (every position, or every n-th of a long flight; the last one always).
    notes : list of str
    """

    info: object
    fences: FenceSet
    near_m: float
    incursions: list = field(default_factory=list)
    closest: dict = field(default_factory=dict)
    alerts: list = field(default_factory=list)
    in_force: dict = field(default_factory=dict)
    start_t: float = math.nan
    end_t: float = math.nan
    track: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    notes: list = field(default_factory=list)

    @property
    def entered(self) -> bool:
        """Did the flight enter a keep-out fence in force, or leave a keep-in fence?"""
        return any(i.kind != "warning" for i in self.incursions)

    def when(self, t) -> str | None:
        """``t`` as UTC ISO 8601 (milliseconds), or None for a log without a wall clock."""
        if t is None or self.info.clock != "utc":
            return None
        return datetime.fromtimestamp(t, timezone.utc).isoformat(timespec="milliseconds")

    def utc(self, t) -> str | None:
        """``t`` (the log's UNIX seconds) as an event's ``utc``, or None for a log without a
        wall clock."""
        return None if t is None or self.info.clock != "utc" else utc_text(t)

    def fence_rows(self) -> list:
        """One dict per fence entered, left or within ``near_m``: incursions first, then by
        closest approach."""
        touched = {i.fence for i in self.incursions}
        rows = []
        for k in touched | set(self.closest):
            r = self.fences.records[k]
            incs = [i for i in self.incursions if i.fence == k]
            a = self.closest.get(k)
            rows.append(
                {
                    "fence": r.site_id,
                    "name": r.name,
                    "kind": r.kind,
                    "alt_min_m": r.alt_min_m,
                    "alt_max_m": r.alt_max_m,
                    "references": [reference(r, "lower"), reference(r, "upper")],
                    "in_force": self.in_force.get(k, "yes"),
                    "incursions": len(incs),
                    "first_in": self.when(incs[0].t_in) if incs else None,
                    "first_in_t": incs[0].t_in if incs else None,
                    "closest": None if a is None else _approach_json(self, a),
                }
            )
        rows.sort(key=lambda d: (d["kind"] == "warning" or not d["incursions"], _closest_m(d)))
        return rows

    def to_json(self) -> dict:
        """The report as plain JSON types (``--json``)."""
        info = self.info
        return {
            "log": {
                "path": info.path,
                "kind": info.kind,
                "source": info.source,
                "sysid": info.sysid,
                "clock": info.clock,
                "start": self.when(self.start_t),
                "end": self.when(self.end_t),
                "start_t": self.start_t,
                "end_t": self.end_t,
                "positions": info.positions,
                "skipped": info.skipped,
                "bad_bytes": info.bad_bytes,
                "truncated": info.truncated,
            },
            "entered": self.entered,
            "incursions": [_incursion_json(self, i) for i in self.incursions],
            "fences": self.fence_rows(),
            "alerts": [
                {**e, "utc": self.utc(e["time"]), "when": self.when(e["time"])} for e in self.alerts
            ],
            "near_m": self.near_m,
            "notes": list(info.notes) + self.notes,
        }


def _closest_m(row):
    return row["closest"]["distance_m"] if row["closest"] else math.inf


def _incursion_json(rep, i):
    r = rep.fences.records[i.fence]
    return {
        "fence": r.site_id,
        "name": r.name,
        "kind": i.kind,
        "in": rep.when(i.t_in),
        "out": rep.when(i.t_out),
        "in_t": i.t_in,
        "out_t": i.t_out,
        "lat": round(i.lat, 7),
        "lon": round(i.lon, 7),
        "alt_m": round(i.alt_m, 2),
        "positions": i.samples,
        "depth_m": round(i.depth_m, 2),
        "between_positions": i.between_samples,
    }


def _approach_json(rep, a):
    return {
        "distance_m": round(a.distance_m, 2),
        "time": rep.when(a.t),
        "t": a.t,
        "lat": round(a.lat, 7),
        "lon": round(a.lon, 7),
        "alt_m": round(a.alt_m, 2),
        "fence_lat": round(a.fence_lat, 7),
        "fence_lon": round(a.fence_lon, 7),
        "in_force": a.in_force,
        "vertical_m": round(a.vertical_m, 2),
    }


def check_flight(log, fences: FenceSet, near_m: float = NEAR_M, options=None) -> FlightReport:
    """Check every position of a flight log against the fences (see the module).

    Parameters
    ----------
    log : FlightLog
    fences : FenceSet
        Its AMSL limits are moved to the log's home for the check (``FenceSet.set_home``;
        a fresh one per log).
    near_m : float
        Closest approaches are measured to fences within this distance of the track.
    options : MonitorOptions, optional
        The engine's (default: alerts only, no onboard fence).

    Returns
    -------
    FlightReport

    Raises
    ------
    InputError
        The log holds no position, or is not a log.
    """
    rep = FlightReport(log.info, fences, near_m)
    engine = Engine(fences, options or MonitorOptions(onboard="off"))
    rep.notes += fences.altitude_notes()
    walker = Walker(rep, engine)
    for chunk in log.chunks():
        rep.info = log.info
        walker.chunk(chunk)
    rep.info = log.info
    walker.finish()
    if fences.timed and log.info.clock != "utc":
        rep.notes.append("no wall-clock time: fences with time windows counted as in force")
    return rep
