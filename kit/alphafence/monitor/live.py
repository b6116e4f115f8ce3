"""Zones from a live source, in flight (``monitor --source URL``).

Every ``refresh_s`` (and at once on :meth:`LiveSource.hint`) the source is asked for the area
that matters: a square of ``radius_m`` around the vehicle, and the mission's waypoints when
the monitor knows them. New and changed zones are read and fenced in a worker process at a
lower priority (:func:`alphafence.fencing.zone_fences.read_answer`), never on the event loop;
the fence set is rebuilt in a worker thread and swapped in between two checks
(:meth:`~alphafence.monitor.runner.Monitor.set_fences`): the rolling onboard fence re-uploads,
the re-route planner is rebuilt, and the engine predicts against the new fences from the next
position on. What is in force follows :class:`~alphafence.monitor.live_zones.LiveZones`: a
failed, partial or empty answer removes nothing.

Events: ``source_answer`` (what came, in how long), ``source_zone`` (a new or changed zone,
its window state), ``source_zone_removed``, ``source_zone_window`` (announced, in force,
ended), ``source_zone_invalid`` (a feature that is not a zone: the others apply),
``source_empty`` (an empty answer where zones were: kept until confirmed), ``source_failed``,
``source_incomplete``, ``source_stale`` and ``source_fresh`` (after ``stale_after_s`` without a
good answer, and back), ``source_clock`` (this clock and the server's differ; windows are
widened by the difference), ``source_fences`` (the fences in force, built and swapped).
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from datetime import datetime, timezone

from alphafence.monitor.events import new_event
from alphafence.monitor.live_parts import (
    LiveOptions,
    one_line,
    pool,
    read_answer,
    short_switches,
    verify,
)
from alphafence.monitor.live_zones import LiveZones, copied_zones, window_state

__all__ = ["LiveOptions", "LiveSource"]

CLOCK_SKEW_S = 30.0  # this clock and the server's differ by more: said, and windows widened
MAX_SKEW_S = 24 * 3600.0  # a server's clock off by more is refused, not applied
BAD_SHOWN = 10  # features that are not zones named one event each, up to this many per answer


class LiveSource:
    """One live source followed by a running monitor.

    Parameters
    ----------
    monitor : Monitor
        Its fences, log, latest position and mission.
    options : LiveOptions
    base : list of FenceRecord
        The fences that are not the source's (``--fences``, less the offline copy's zones).
    copied : list of FenceRecord
        The offline copy's fences of the source's zones (``source_zone``/``source_hash``):
        in force until a complete answer drops them.
    """

    def __init__(self, monitor, options: LiveOptions, base, copied=()):
        self.monitor, self.options = monitor, options
        self.base = list(base)
        self.fenced = {}  # zone hash -> [FenceRecord] (or the worker's packed fences, unread)
        self.zones = LiveZones(copied_zones(copied, self.fenced))
        self.etag = self.last_modified = None
        self.last_good = time.monotonic()
        self.stale = False
        self.skew_s = 0.0
        self._skew_refused = False
        self._awaiting_position = False
        self.windows = {}  # zone hash -> the window state last said
        self._timed = None  # (the zone set's revision, its zones with a window)
        self.answers = 0
        self.pool = None
        self._wake = asyncio.Event()
        self.refreshes = 0  # refreshes ended, whatever came of them
        self.known = options.from_file  # what is in force is known (a file, or a complete answer)
        self._refreshed = asyncio.Condition()
        self._http = None

    def hint(self) -> None:
        """Ask the source now, not at the next refresh (a ground station's word)."""
        self._wake.set()

    async def run(self, stop: asyncio.Event) -> None:
        """Ask the source until ``stop`` is set (the monitor runs it as a task). Supervised:
        whatever a refresh raises is one ``source_failed`` and the next refresh comes as due;
        a worker or session that cannot be opened is tried again at the next refresh."""
        while not stop.is_set():
            try:
                async with self.opened():
                    while not stop.is_set():
                        self._wake.clear()  # a hint during the refresh asks again at once
                        await self.refresh()
                        await self._pause()
            except Exception as exc:  # noqa: BLE001 - the loop outlives anything it meets
                self._failed(f"the source's worker or session failed: {one_line(exc)}")
                self._wake.clear()
                await self._pause()

    async def _pause(self) -> None:
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(self._wake.wait(), self.options.refresh_s)

    async def next_refresh(self) -> None:
        """Wait for the end of the next refresh (the one under way, or the next to start)."""
        done = self.refreshes
        async with self._refreshed:
            await self._refreshed.wait_for(lambda: self.refreshes > done)

    @contextlib.asynccontextmanager
    async def opened(self):
        """The worker process (spawned, not forked: the monitor has threads) and the HTTP
        session, for :meth:`refresh`; both closed at the end."""
        from alphafence.sources.ogc import session

        self.pool = pool()
        self._http = session(self.options.source)
        try:
            yield self
        finally:
            await self._http.close()
            self.pool.shutdown(wait=False, cancel_futures=True)

    def area(self):
        """The lon/lat box asked: around the vehicle and the mission's waypoints (before the
        first position: around every fence; None without either)."""
        from alphafence.geo.frame import LocalFrame

        points = []
        latest = self.monitor.engine.last
        if latest is not None:
            points.append((latest.lon, latest.lat))
        mission = getattr(self.monitor.reroute, "mission", None)
        for item in (mission[1] if mission else None) or ():
            lat, lon = getattr(item, "x", 0) / 1e7, getattr(item, "y", 0) / 1e7
            if lat or lon:
                points.append((lon, lat))
        records = self.monitor.engine.fences.records
        if not points and not records:
            return None  # no position yet, no fence: asked once the vehicle's position comes
        if not points:  # around every fence (their lon/lat bounds)
            import shapely

            b = shapely.total_bounds([r.geometry for r in records])
            points = [(b[0], b[1]), (b[2], b[3])]
        r, boxes = self.options.radius_m, []
        for lon, lat in points:
            frame = LocalFrame(lon, lat)
            lons, lats = frame.to_wgs84([-r, r], [-r, r])
            boxes.append((min(lons), min(lats), max(lons), max(lats)))
        return (min(b[0] for b in boxes), min(b[1] for b in boxes),
                max(b[2] for b in boxes), max(b[3] for b in boxes))  # fmt: skip

    async def refresh(self) -> None:
        """One answer: asked, read and fenced in the worker, taken, the fences swapped if
        anything changed. Never raises but for cancellation: any failure, the source's or a
        bug's, is one ``source_failed`` and removes nothing."""
        try:
            await self._refresh()
        except Exception as exc:  # noqa: BLE001 - what a server sent must not end the polling
            self._failed(f"refresh failed: {one_line(exc)}")
        finally:
            self.refreshes += 1
            async with self._refreshed:
                self._refreshed.notify_all()

    def _failed(self, error: str) -> None:
        self.monitor.handle(new_event("source_failed", error=error, kept=len(self.zones.versions)))
        self._check_stale()

    async def _refresh(self) -> None:
        from concurrent.futures.process import BrokenProcessPool

        from alphafence.errors import SourceError
        from alphafence.sources.ogc import fetch

        put = self.monitor.handle  # logged, and alerted when it says something to the GCS
        bbox = self.area()
        if bbox is None:
            self._awaiting_position = True  # tick() asks as soon as a position comes
            return
        try:
            answer = await fetch(self._http, self.options.source, bbox, self.etag,
                                 self.last_modified, keep="raw")  # fmt: skip
            if answer.raw is not None and self.options.trusted_keys:
                await verify(self._http, self.options, answer)
        except SourceError as exc:
            self._failed(str(exc))
            return
        self.answers += 1
        self._clock(answer)
        if answer.not_modified:
            self._good()
            put(new_event("source_answer", not_modified=True, seconds=round(answer.seconds, 3)))
            return
        loop = asyncio.get_running_loop()
        try:
            entries, bad, fences = await loop.run_in_executor(
                self.pool, read_answer, self.options, answer.pages_raw, set(self.fenced)
            )
        except BrokenProcessPool:  # the worker died (killed, out of memory): a new one next
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = pool()
            self._failed("reading the answer: the worker process died (a new one is started)")
            return
        except Exception as exc:  # noqa: BLE001 - a worker that failed removes nothing
            self._failed(f"reading the answer: {one_line(exc)}")
            return
        zones, held = self._zones(entries, fences)
        for line in bad[:BAD_SHOWN]:
            put(new_event("source_zone_invalid", problem=line))
        if answer.count and not zones:  # every feature malformed: no answer, never an empty one
            self._failed(f"{answer.url}: none of its {answer.count} features is a zone: taken as "
                         "a failed answer")  # fmt: skip
            return
        change = self.zones.answer(zones, answer.complete, bbox, held)
        self._said(answer, zones, bad, change)
        if change:
            await self._swap()

    def _said(self, answer, zones, bad, change) -> None:
        """The events of an answer taken: what came, the zones new, changed, kept or lifted."""
        put = self.monitor.handle
        put(new_event("source_answer", zones=len(zones), invalid=len(bad), pages=answer.pages,
                      complete=answer.complete, seconds=round(answer.seconds, 3),
                      bytes=answer.bytes))  # fmt: skip
        if answer.complete:
            self.etag, self.last_modified = answer.etag, answer.last_modified
            self._good()
            if not self.known:
                self.known = True
                put(new_event("source_known", zones=len(zones),
                              reason="the source's first complete answer: its zones are in "
                              "force"))  # fmt: skip
        else:
            put(
                new_event(
                    "source_incomplete", error=str(answer.error), kept=len(self.zones.versions)
                )
            )
            self._check_stale()
        if change.kept_empty:
            put(new_event("source_empty", kept=[z.id for z in change.kept_empty][:20],
                          reason="an empty answer where zones were: kept until a second one"))  # fmt: skip
        for z in change.held:
            put(new_event("source_zone_kept", zone=z.id, name=z.name,
                          reason="served malformed: kept as it was"))  # fmt: skip
        now = datetime.now(timezone.utc)
        for z in change.added + change.changed:
            state = window_state(z.applicability, now, self.options.announce_s, self.skew_s)
            self.windows[z.hash] = state
            put(new_event("source_zone", zone=z.id, name=z.name, change="changed" if z in change.changed else "new",
                          kinds=self._kinds(z.hash),
                          window=state, applicability=z.applicability, source=answer.url))  # fmt: skip
        for z in change.removed:
            self.windows.pop(z.hash, None)
            put(new_event("source_zone_removed", zone=z.id, name=z.name))

    def tick(self, now_utc) -> None:
        """Each second: windows that changed state are said; the source gone stale is. Only
        the zones with a window are looked at (the others are always in force)."""
        from alphafence.awareness.applicability import timed

        if self._awaiting_position and self.monitor.engine.last is not None:
            self._awaiting_position = False
            self.hint()
        if self._timed is None or self._timed[0] != self.zones.revision:
            windowed = [z for z in self.zones.zones if timed(z.applicability)]
            self._timed = (self.zones.revision, windowed)
        for z in self._timed[1]:
            try:
                state = window_state(z.applicability, now_utc, self.options.announce_s, self.skew_s)
            except Exception as exc:  # noqa: BLE001 - a served window this clock cannot take
                state = f"unreadable ({one_line(exc)}): in force"
            if self.windows.get(z.hash) != state:
                self.windows[z.hash] = state
                self.monitor.handle(
                    new_event("source_zone_window", zone=z.id, name=z.name, window=state)
                )
        self._check_stale()

    def records(self) -> list:
        """Every fence in force: the base's, then each zone version's (the worker's packed
        fences read first, all in one call)."""
        from alphafence.fencing.zone_fences import unpack

        hashes = [z.hash for z in self.zones.zones]
        packed = [h for h in hashes if self.fenced.get(h) and isinstance(self.fenced[h][0], tuple)]
        if packed:
            read = iter(
                unpack(self.options.source.url, [p for h in packed for p in self.fenced[h]])
            )
            for h in packed:
                self.fenced[h] = [next(read) for _ in self.fenced[h]]
        return self.base + [r for h in hashes for r in self.fenced.get(h, ())]

    def _kinds(self, digest) -> list:
        got = self.fenced.get(digest, ())
        return sorted({r[0]["kind"] if isinstance(r, tuple) else r.kind for r in got})

    async def _swap(self) -> None:
        from alphafence.awareness.fenceset import FenceSet

        t0 = time.monotonic()
        current = self.monitor.engine.fences
        # a set of no fence has a frame of no place: the first fences get one of their own
        frame = current.frame if current.records else None
        records = None

        def build():  # the new zones' records read and the set indexed: a worker thread
            nonlocal records
            records = self.records()
            fs = FenceSet(records, frame=frame)
            fs.index()
            return fs

        try:
            with short_switches():
                fences = await asyncio.to_thread(build)
        except ValueError:  # no fence at all: the set in use stays (it holds more, not less)
            self.monitor.log.put(new_event("source_fences", fences=0, kept=True))
            return
        self.monitor.set_fences(fences)
        self.monitor.log.put(new_event("source_fences", fences=len(records),
                                       live=len(records) - len(self.base),
                                       seconds=round(time.monotonic() - t0, 3)))  # fmt: skip

    def _zones(self, entries, fences):
        """The zones of the worker's entries, and the ids it held (served malformed)."""
        zones, held, by_hash = [], [], {z.hash: z for z in self.zones.zones}
        for entry in entries:
            if entry[0] == "held":
                held.append(entry[1])
            elif entry[0] == "known":
                z = by_hash.get(entry[2]) or self._known.get(entry[2])
                if z is not None:
                    zones.append(z)
            else:
                z = entry[1]
                self.fenced[z.hash] = fences.get(z.hash, [])  # read in the worker
                self._known[z.hash] = z
                zones.append(z)
        return zones, held

    @property
    def _known(self) -> dict:
        if not hasattr(self, "_known_zones"):
            self._known_zones = {z.hash: z for z in self.zones.zones}
        return self._known_zones

    def _good(self) -> None:
        self.last_good = time.monotonic()
        if self.stale:
            self.stale = False
            self.monitor.handle(new_event("source_fresh"))

    def _check_stale(self) -> None:
        quiet = time.monotonic() - self.last_good
        if not self.stale and quiet > self.options.stale_s:
            self.stale = True
            self.monitor.handle(new_event("source_stale", seconds=round(quiet, 1),
                                          kept=len(self.zones.versions)))  # fmt: skip

    def _clock(self, answer) -> None:
        """The server's clock against this one: windows widened by a difference over
        :data:`CLOCK_SKEW_S`; one over :data:`MAX_SKEW_S` is the server's fault, refused (said
        once, nothing widened)."""
        skew = answer.server_skew_s
        if skew is None or skew != skew:
            return
        if abs(skew) > MAX_SKEW_S:
            if not self._skew_refused:
                self._skew_refused = True
                self.monitor.handle(new_event("source_clock", skew_s=round(max(-1e12, min(1e12, skew)), 1),
                                              refused=True, reason="the source's clock is off by "
                                              f"more than {MAX_SKEW_S / 3600:g} h: its Date is not "
                                              "applied"))  # fmt: skip
            return
        self._skew_refused = False
        doubt = abs(skew) if abs(skew) > CLOCK_SKEW_S else 0.0
        if doubt and not self.skew_s:
            self.monitor.handle(new_event("source_clock", skew_s=round(skew, 1),
                                          reason="this clock and the source's differ: zone "
                                          "windows are widened by the difference"))  # fmt: skip
        self.skew_s = doubt
        self.monitor.clock_slack_s = doubt
