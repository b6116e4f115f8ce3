"""The rolling onboard fence: the vehicle's fence kept equal to the compiled fences within reach.

A vehicle with a small fence storage (a Copter's 560 bytes) cannot hold every fence of a large
area at full resolution, but it only needs those it can reach. The *reach* is what it can fly
in a lookahead at its speed limit and then stop (:class:`~alphafence.monitor.options.
RollingOptions`). The monitor compiles the keep-out and keep-in fences within a *radius* of
where the vehicle is (the reach, plus the hysteresis, plus what it flies while a re-upload is
under way), uploads them, reads them back, and does it again once the vehicle is the
hysteresis away from that centre. So the fence in force always holds every fence within reach
of the vehicle, the previous one until the new one is written (ArduPilot keeps its fence until
the last item of an upload arrives, and keeps it when an upload fails; PX4 writes an upload
into its other fence slot and switches at its end). Each compile leaves the vehicle's home and position
clear (:mod:`alphafence.onboard.clear`) and writes several keep-in areas as its firmware reads
them (:func:`~alphafence.vehicle.params.inclusion_rule`); on PX4 the fence is checked against
its home before it is sent.

:class:`RollingPlan` is the pure part (which fences, when to re-upload); :class:`RollingFence`
does it on the event loop: the compile in a worker thread, the upload and read-back as a task
of its own, every upload an event (``onboard_upload`` or ``onboard_upload_failed``, alerted),
and the monitor's onboard layer reloaded after each one. A compile that makes the fence the
vehicle already holds, or no fence at all (none within the radius), sends nothing
(``onboard_kept``).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from dataclasses import dataclass

import numpy as np
import shapely

from alphafence.awareness.fenceset import KEEP_IN, KEEP_OUT
from alphafence.mavlink.autopilots import NAMES
from alphafence.mavlink.inclusions import needs_union
from alphafence.monitor.events import new_event, rounded
from alphafence.vehicle.params import inclusion_rule
from alphafence.vehicle.px4 import check_home, confirm_kept
from alphafence.vehicle.whereabouts import HomeWatch

RADIUS_SLACK_M = 1.0  # the compile selects this much farther than the plan (frames differ)


@dataclass(frozen=True)
class Coverage:
    """Where a rolling fence was compiled for, and what it holds.

    Attributes
    ----------
    x, y : float
        Its centre in the monitor's metric frame.
    lon, lat : float
        Its centre (WGS84).
    radius_m : float
        The fences within this distance of the centre are in it.
    sites : frozenset of str
        The site ids of the fences compiled.
    version : int
        The fence set's ``version`` it was compiled from (what is in force, by time window).
    """

    x: float
    y: float
    lon: float
    lat: float
    radius_m: float
    sites: frozenset
    version: int = 0


class RollingPlan:
    """Which fences a rolling fence holds and when to re-upload it (pure).

    Parameters
    ----------
    fences : FenceSet
        The full-resolution fences (the monitor's).
    reach_m, trigger_m, radius_m : float
        From :class:`~alphafence.monitor.options.RollingOptions`: the vehicle's reach, the
        distance from the centre that calls for a new fence, and the radius of a fence.

    Examples
    --------
    >>> from alphafence.fencefiles.fence_geojson import FenceRecord
    >>> from alphafence.awareness.fenceset import FenceSet
    >>> from alphafence.geo.frame import LocalFrame
    >>> frame = LocalFrame(14.5, 35.9)
    >>> square = frame.geom_to_wgs84(shapely.box(400, -10, 420, 10))
    >>> plan = RollingPlan(FenceSet([FenceRecord("a", "keep_out", square)], frame), 100, 25, 150)
    >>> plan.within(0.0, 0.0, 100.0), plan.within(300.0, 0.0, 100.0)
    ([], ['a'])
    >>> c = plan.coverage(0.0, 0.0, 14.5, 35.9)
    >>> plan.due(None, 0, 0), plan.due(c, 20, 0), plan.due(c, 30, 0), plan.due(c, 60, 0)
    ('start', None, 'moved', 'uncovered')
    """

    def __init__(self, fences, reach_m: float, trigger_m: float, radius_m: float):
        self.fences = fences
        self.frame = fences.frame  # the plan's own (the fence set's, when it was made)
        self.reach_m = float(reach_m)
        self.trigger_m = float(trigger_m)
        self.radius_m = float(radius_m)
        self._onboard = np.flatnonzero(np.isin(fences.kind, (KEEP_OUT, KEEP_IN)))
        self._tree = shapely.STRtree(fences.local[self._onboard])

    def indices(self, x: float, y: float, distance_m: float) -> list:
        """The keep-out and keep-in fences in force within ``distance_m`` of ``(x, y)``
        (indices into the fence set, ascending)."""
        hit = self._tree.query(shapely.Point(x, y), predicate="dwithin", distance=distance_m)
        active = self.fences.active  # a time-windowed fence only while its window is open
        return sorted(int(self._onboard[i]) for i in hit if active[self._onboard[i]])

    def within(self, x: float, y: float, distance_m: float) -> list:
        """The site ids of the keep-out and keep-in fences within ``distance_m`` of ``(x, y)``."""
        return [self.fences.records[i].site_id for i in self.indices(x, y, distance_m)]

    def coverage(self, x: float, y: float, lon: float, lat: float) -> Coverage:
        """The :class:`Coverage` of a fence compiled around ``(x, y)`` (``lon``, ``lat``)."""
        sites = frozenset(self.within(x, y, self.radius_m))
        return Coverage(
            float(x), float(y), float(lon), float(lat), self.radius_m, sites, self.fences.version
        )

    def records(self, coverage: Coverage) -> list:
        """The fence records a fence of ``coverage`` is compiled from."""
        return [self.fences.records[i] for i in self.indices(coverage.x, coverage.y, self.radius_m)]

    def covers(self, coverage: Coverage | None, x: float, y: float) -> bool:
        """Does the fence of ``coverage`` hold every fence within reach of ``(x, y)``? (Its
        disk holds the reach's, or at least every fence within reach is in it.)"""
        if coverage is None:
            return False
        if math.hypot(x - coverage.x, y - coverage.y) + self.reach_m <= coverage.radius_m:
            return True
        return set(self.within(x, y, self.reach_m)) <= coverage.sites

    def due(self, coverage: Coverage | None, x: float, y: float) -> str | None:
        """Why a new fence is due at ``(x, y)``, or None.

        Returns
        -------
        str or None
            ``"start"`` (no fence yet), ``"windows"`` (a fence's time window opened or
            closed since), ``"uncovered"`` (the fence in force no longer holds the whole
            reach), ``"moved"`` (farther than the trigger distance from its centre), or None.
        """
        if coverage is None:
            return "start"
        if coverage.version != self.fences.version:
            return "windows"
        d = math.hypot(x - coverage.x, y - coverage.y)
        if d + self.reach_m > coverage.radius_m:
            return "uncovered"
        return "moved" if d > self.trigger_m else None


class RollingFence:
    """The monitor's rolling onboard fence on one vehicle (``--onboard rolling``).

    Parameters
    ----------
    vehicle : Vehicle
    fences : FenceSet
        The full-resolution fences.
    options : RollingOptions
        The profile, the speed limit and lookahead, the hysteresis.
    braking : Braking
        How the vehicle stops.
    handle : callable
        ``handle(event)``: the monitor's (logs, alerts).
    reload : coroutine function
        ``await reload(cause)``: download the vehicle's fence into the onboard layer (the
        monitor's :meth:`~alphafence.monitor.runner.Monitor.reload_onboard`).

    Attributes
    ----------
    plan : RollingPlan
    coverage : Coverage or None
        What the verified fence in force was compiled for.
    task, after : asyncio.Task or None
        The compile and upload under way (or the last one); a fence transfer (the monitor's
        first download) the first upload waits for.
    uploads : int
        Verified uploads so far.
    held : list of FenceItem or None
        The fence of the last verified upload (the same items again send nothing:
        ``onboard_kept``); None after a failed upload.
    """

    def __init__(self, vehicle, fences, options, braking, handle, reload):
        from alphafence.mavlink.storage import vehicle_profile

        self.vehicle = vehicle
        self.options = options
        self.autopilot = getattr(vehicle, "autopilot", "ardupilot")
        self.profile = vehicle_profile(options.profile, self.autopilot)  # InputError if not its
        self.plan = RollingPlan(
            fences, options.reach_m(braking), options.trigger_m(braking), options.radius_m(braking)
        )
        self.handle = handle
        self.reload = reload
        self.coverage: Coverage | None = None
        self.task: asyncio.Task | None = None
        self.uploads = 0
        self._retry_at = -math.inf
        self._uncovered = False
        self.after: asyncio.Task | None = None  # a transfer to wait for before uploading
        self.held: list | None = None  # the items of the last verified upload
        self.homes = HomeWatch(vehicle)  # no compile covers home (nor the vehicle)
        self.rule: tuple | None = None  # (rule, FENCE_OPTIONS, why): params.inclusion_rule

    def set_fences(self, fences) -> None:
        """Compile from ``fences`` from now on: the next position starts a re-upload (one under
        way finishes first; a compile that makes the same items sends nothing)."""
        p = self.plan
        self.plan = RollingPlan(fences, p.reach_m, p.trigger_m, p.radius_m)
        self.coverage = None  # an upload under way finishes, and covers the old fences only

    def consider(self, sample) -> asyncio.Task | None:
        """Look at a new position: start a re-upload when one is due and none is under way,
        and say once when the fence in force no longer holds the vehicle's reach.

        Parameters
        ----------
        sample : Sample
            The vehicle's position (``t``, ``lat``, ``lon``).

        Returns
        -------
        asyncio.Task or None
            The re-upload started, if one was.
        """
        x, y = (float(v) for v in self.plan.frame.to_local(sample.lon, sample.lat))
        why = self.plan.due(self.coverage, x, y)
        if why is None:
            self._uncovered = False
            return None
        if self.coverage is not None:
            covered = self.plan.covers(self.coverage, x, y)
            if not covered and not self._uncovered:
                self.handle(
                    new_event(
                        "onboard_behind",
                        sample.t,
                        sample,
                        reach_m=rounded(self.plan.reach_m),
                        centre=[rounded(self.coverage.lat, 7), rounded(self.coverage.lon, 7)],
                        reason="the vehicle's fence no longer holds every fence within reach",
                    )
                )
            self._uncovered = not covered
        busy = self.task is not None and not self.task.done()
        if busy or time.monotonic() < self._retry_at:
            return None
        target = self.plan.coverage(x, y, sample.lon, sample.lat)
        self.task = asyncio.create_task(self._roll(target, why, sample), name="onboard:rolling")
        return self.task

    async def _roll(self, target: Coverage, why: str, sample) -> bool:
        """Compile (worker thread), upload and read back one fence; the event, then the
        onboard layer reloaded. Returns whether the vehicle now holds it."""
        from alphafence.errors import AlphaFenceError
        from alphafence.onboard.clear import KeepClear
        from alphafence.onboard.compile import compile_fences
        from alphafence.vehicle.fence_transfer import same_items

        t0, plan = time.monotonic(), self.plan
        fields = {"reason": why, "centre": [rounded(target.lat, 7), rounded(target.lon, 7)],
                  "reach_m": rounded(self.plan.reach_m), "radius_m": rounded(target.radius_m),
                  "fences": len(target.sites)}  # fmt: skip
        home = await self.homes.current()
        if self.rule is None:  # how it reads several keep-in areas: by its firmware
            self.rule = await inclusion_rule(self.vehicle)
        keep = KeepClear.of(home, (sample.lon, sample.lat), self.options.home_clearance_m, False)
        try:
            compiled = await asyncio.to_thread(
                compile_fences, plan.records(target), shapely.Point(target.lon, target.lat),
                self.profile, target.radius_m + RADIUS_SLACK_M, keep_clear=keep,
                inclusions=self.rule[0])  # fmt: skip
        except asyncio.CancelledError:
            raise
        except AlphaFenceError as exc:  # the fences within reach do not fit even merged
            return self._failed(t0, "compile", str(exc), None, fields)
        fields.update(items=len(compiled.items), bytes=compiled.bytes_used)
        fields.update(merges=len(compiled.merges), compile_s=rounded(time.monotonic() - t0, 3))
        same = self.held is not None and same_items(compiled.items, self.held) == []
        if same or not compiled.items:  # nothing to send: it holds this very fence, or no
            self.coverage = target if self.plan is plan else None  # nothing within the radius
            self.handle(new_event("onboard_kept", None, None, **fields))
            return True
        if self.after is not None:  # the monitor's first download: one transfer at a time
            await asyncio.wait([self.after])
        if self.autopilot == "px4":  # PX4 would drop an area its home breaches, silently
            try:
                await check_home(self.vehicle, compiled.items)
            except Exception as exc:  # noqa: BLE001 - an event, never a crash
                return self._failed(t0, "home", str(exc), None, fields)
        ok = await self._upload(compiled.items, t0, target, fields)
        if self.plan is not plan:  # new fences came meanwhile: compile again
            self.coverage = None
        await self.reload("rolling")
        return ok

    async def _upload(self, items, t0, target, fields) -> bool:
        from alphafence.vehicle.fence_transfer import FenceTransferError, upload_fence

        try:
            report = await upload_fence(self.vehicle, items, capacity=self.profile.items)
        except asyncio.CancelledError:
            raise
        except FenceTransferError as exc:
            return self._failed(t0, "upload", str(exc), exc.holds, fields)
        except Exception as exc:  # the link failed under MAVSDK: an event, never a crash
            return self._failed(t0, "upload", f"{type(exc).__name__}: {exc}", None, fields)
        if self.autopilot == "px4":  # and PX4 keeps every area (home, and its own words)
            try:
                await confirm_kept(self.vehicle, items, t0)
            except Exception as exc:  # noqa: BLE001 - it says what the vehicle holds
                return self._failed(t0, "confirm", str(exc), str(exc), fields)
        self.coverage, self.held = target, list(items)
        self.uploads += 1
        self._uncovered = False
        if needs_union(items):  # more than one inclusion: ArduPilot must read their union
            fields["inclusions"] = await self._union(items)
        self.handle(
            new_event(
                "onboard_upload",
                None,
                None,
                **fields,
                started=rounded(t0, 3),
                upload_s=rounded(report.seconds, 3),
                seconds=rounded(time.monotonic() - t0, 3),
                verified=report.verified,
            )
        )
        return True

    async def _union(self, items) -> str:
        """Set FENCE_OPTIONS' union bit for a fence of several inclusions: ``"union"``, or
        what failed (the vehicle then intersects them: the reload's event warns)."""
        from alphafence.vehicle.params import set_union

        try:
            rule, options, why = self.rule
            if rule != "union":
                return f"intersection: {why}"
            await set_union(self.vehicle, options)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # an event, never a crash
            return f"intersection: {exc}"
        return "union"

    def _failed(self, t0, stage, error, holds, fields) -> bool:
        if stage == "upload":
            self.held = None  # what it holds now is read back by the reload, not assumed
        self._retry_at = time.monotonic() + self.options.retry_s
        kept = holds or (
            f"the previous fence ({NAMES[self.autopilot]} keeps it when an upload fails)"
            if stage == "upload"
            else "the previous fence (nothing was sent)"
        )
        self.handle(
            new_event(
                "onboard_upload_failed",
                None,
                None,
                **fields,
                stage=stage,
                error=error,
                kept=kept,
                started=rounded(t0, 3),
                seconds=rounded(time.monotonic() - t0, 3),
                verified=False,
            )
        )
        return False

    async def finish(self, timeout: float) -> None:
        """Let a fence transfer under way end before the monitor stops (at most ``timeout``
        seconds): MAVSDK cannot be interrupted mid-transfer (its call runs on in a worker
        thread that the event loop's shutdown would wait for), and then the vehicle holds a
        verified fence or the failure is logged."""
        self.homes.close()
        task = self.task
        if task is None or task.done():
            return
        with contextlib.suppress(asyncio.CancelledError, asyncio.TimeoutError, Exception):
            await asyncio.wait_for(asyncio.shield(task), timeout)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task
