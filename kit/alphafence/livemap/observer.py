"""The live map's side of the monitor: an :class:`~alphafence.monitor.observe.Observer` that
keeps what the pages show and a bounded queue per page, never slowing the checks.

The observer's callbacks only note things: the latest step replaces the one before (positions
are coalesced to the latest), an aircraft's latest report replaces its last, and each event is
put in every page's queue, which holds at most ``queue_max`` messages (the oldest is dropped
and counted, and the page is told how many). Each page has a sender task (:meth:`LiveMap.serve`)
that wakes when there is something new, builds the messages (:mod:`alphafence.livemap.view`;
the fences near the vehicle in a worker thread) and sends them; a page that takes longer than
``send_timeout_s`` to accept one message is dropped. The map is read-only: nothing here talks
to the vehicle.
"""

from __future__ import annotations

import asyncio
import json
from collections import deque

from alphafence.awareness.traffic import TrafficOptions
from alphafence.geo.frame import short_distance_m
from alphafence.livemap.view import (
    NearFences,
    onboard_message,
    traffic_message,
    vehicle_message,
)
from alphafence.monitor.observe import Observer

OSM_ATTRIBUTION = "© OpenStreetMap contributors (ODbL)"
QUEUE_MAX = 256  # messages waiting for one page (events, fences); the oldest is dropped
SEND_TIMEOUT_S = 5.0  # a page that takes longer than this to accept one message is dropped
NEAR_M = 5000.0  # the full-resolution fences within this of the vehicle are sent
HISTORY = 200  # the latest events a page gets when it connects
VEHICLE_EVERY_S = 0.05  # at most 20 vehicle messages a second per page (the latest each time)
ONBOARD_EVENTS = {"onboard_fence", "onboard_none", "onboard_upload"}
TRAFFIC_STREAMS = {"adsb", "traffic"}


class LiveClient:
    """One page's queue: events and other messages in order, at most ``maxlen`` (the oldest
    dropped and counted), and flags for what is rebuilt from the latest state when sent.

    Parameters
    ----------
    maxlen : int
        The most messages kept waiting.

    Attributes
    ----------
    queue : collections.deque
    dropped : int
        Messages dropped so far (the page is told).
    peak : int
        The longest the queue has been.
    """

    def __init__(self, maxlen: int = QUEUE_MAX):
        self.maxlen = maxlen
        self.queue: deque = deque()
        self.dropped = 0
        self.told_dropped = 0
        self.peak = 0
        self.wake = asyncio.Event()
        self.vehicle_due = self.traffic_due = self.onboard_due = False
        self.near_center = None  # where the fences it has were gathered around

    def put(self, message) -> None:
        """Queue ``message`` (a dict, or its JSON text), dropping the oldest when full."""
        if len(self.queue) >= self.maxlen:
            self.queue.popleft()
            self.dropped += 1
        self.queue.append(message)
        self.peak = max(self.peak, len(self.queue))
        self.wake.set()


class LiveMap(Observer):
    """What the live map's pages show, kept up to date from the monitor.

    Parameters
    ----------
    fences : FenceSet
        The full-resolution fences.
    near_m : float
        The fences within this of the vehicle are sent (again once it has moved a quarter
        of this from where they were gathered).
    queue_max : int
        Messages kept waiting per page.
    send_timeout_s : float
        A page that takes longer to accept one message is dropped.
    vehicle_every_s : float
        The least time between two vehicle messages to a page (the latest step is sent).
    basemap : dict, optional
        A GeoJSON FeatureCollection each page draws beneath everything (an OpenStreetMap
        extract's roads, water and place names: ``monitor --basemap``).

    Attributes
    ----------
    clients : set of LiveClient
    dropped_clients : int
        Pages dropped for not keeping up.
    steps : int
        Engine steps seen.
    opened : asyncio.Event
        Set once a page has connected.
    """

    def __init__(
        self,
        fences,
        near_m=NEAR_M,
        queue_max=QUEUE_MAX,
        send_timeout_s=SEND_TIMEOUT_S,
        vehicle_every_s=VEHICLE_EVERY_S,
        basemap=None,
    ):
        self.near = NearFences(fences.records)
        self.near_records = self.near.records  # what the next gathering indexes
        self.basemap = basemap  # a GeoJSON FeatureCollection drawn beneath (an OSM extract's)
        self.near_m = float(near_m)
        self.queue_max = queue_max
        self.send_timeout_s = send_timeout_s
        self.vehicle_every_s = vehicle_every_s
        self.clients: set = set()
        self.dropped_clients = 0
        self.steps = 0
        self.step = None
        self.engine = None
        self.options = None
        self.aircraft: dict = {}
        self.events: deque = deque(maxlen=HISTORY)
        self.onboard_cause = None
        self._near = None  # (center lon, lat, text)
        self.opened = asyncio.Event()  # set when the first page connects
        self._near_task = None

    # -- the observer: note, never build or send ----------------------------------
    def on_engine(self, engine) -> None:
        """Keep the engine: its options, its onboard layer (read when sent)."""
        self.engine, self.options = engine, engine.options

    def on_value(self, stream: str, t: float, value) -> None:
        """Keep each aircraft's latest report."""
        if stream in TRAFFIC_STREAMS and isinstance(value, dict) and "key" in value:
            self.aircraft[value["key"]] = (t, value)
            for c in self.clients:
                c.traffic_due = True
                c.wake.set()

    def on_step(self, step) -> None:
        """Keep the latest step; every page is due a vehicle message."""
        self.step = step
        self.steps += 1
        for c in self.clients:
            c.vehicle_due = True
            c.traffic_due = c.traffic_due or bool(self.aircraft)
            c.wake.set()

    def on_event(self, event: dict) -> None:
        """Queue the event for every page (and the vehicle's fence, when it changed; the
        fences near the vehicle again, when a live source's zones changed them)."""
        self.events.append(event)
        if event.get("event") == "source_fences" and self.engine is not None:
            self.near_records = self.engine.fences.records  # indexed at the next gathering
            self._near = None
            for c in self.clients:
                c.near_center = None
                c.vehicle_due = True
                c.wake.set()
        onboard = event.get("event") in ONBOARD_EVENTS
        if onboard:
            self.onboard_cause = event.get("cause") or event.get("reason") or event["event"]
        for c in self.clients:
            c.put({"type": "event", "event": event})
            c.onboard_due = c.onboard_due or onboard

    # -- the pages ----------------------------------------------------------------
    def connect(self) -> LiveClient:
        """A new page: its queue, due everything."""
        c = LiveClient(self.queue_max)
        c.vehicle_due = c.onboard_due = c.traffic_due = True
        c.wake.set()
        self.clients.add(c)
        self.opened.set()
        return c

    def disconnect(self, client: LiveClient) -> None:
        """The page is gone: nothing more is queued for it."""
        self.clients.discard(client)

    def hello(self) -> dict:
        """The first message a page gets: the look-ahead, the braking model and the latest
        events."""
        o = self.options
        return {
            "type": "hello",
            "near_m": self.near_m,
            "horizon_s": None if o is None else o.horizon_s,
            "enforce": None if o is None else o.enforce,
            "events": list(self.events),
        }

    async def serve(self, client: LiveClient, send) -> None:
        """Send ``client`` what is new until it is gone; ``send(text)`` sends one message.

        Raises
        ------
        asyncio.TimeoutError
            When one message took longer than ``send_timeout_s`` to send: the page cannot
            keep up (``dropped_clients`` counts it).
        """
        loop = asyncio.get_running_loop()
        last_vehicle = -1e9
        try:
            await self._send(send, self.hello())
            if self.basemap is not None:
                await self._send(send, {"type": "basemap", "geojson": self.basemap,
                                        "attribution": OSM_ATTRIBUTION})  # fmt: skip
            while True:
                await client.wake.wait()
                client.wake.clear()
                if client.vehicle_due and self.step is not None:
                    wait = last_vehicle + self.vehicle_every_s - loop.time()
                    if wait > 0:  # coalesce: the latest step when the gap is over
                        await asyncio.sleep(wait)
                    for message in await self._vehicle_messages(client):
                        await self._send(send, message)
                    last_vehicle = loop.time()
                while client.queue:
                    await self._send(send, client.queue.popleft())
                if client.dropped > client.told_dropped:
                    client.told_dropped = client.dropped
                    await self._send(send, {"type": "dropped", "messages": client.dropped})
                if client.onboard_due and self.engine is not None:
                    client.onboard_due = False
                    layer = self.engine.onboard
                    await self._send(send, onboard_message(layer, self.onboard_cause))
                if client.traffic_due:
                    client.traffic_due = False
                    conflicts = set() if self.engine is None else self.engine.conflicts
                    options = self.options.traffic if self.options else TrafficOptions()
                    message = traffic_message(self.aircraft, self.step, options, conflicts)
                    await self._send(send, message)
        except asyncio.TimeoutError:
            self.dropped_clients += 1
            raise
        finally:
            self.disconnect(client)

    async def _send(self, send, message) -> None:
        text = message if isinstance(message, str) else json.dumps(message, allow_nan=False)
        await asyncio.wait_for(send(text), self.send_timeout_s)

    async def _vehicle_messages(self, client) -> list:
        """The vehicle's message, after the fences near it when it has moved far enough
        from where the page's fences were gathered."""
        client.vehicle_due = False
        step = self.step
        s = step.sample
        out = []
        c = client.near_center
        if c is None or short_distance_m((c[1], c[0]), (s.lat, s.lon)) > self.near_m / 4:
            center, text = await self._near_fences(s.lon, s.lat)
            client.near_center = center
            out.append(text)
        checks = 0 if self.engine is None else self.engine.checks
        out.append(vehicle_message(step, self.options, checks))
        return out

    async def _near_fences(self, lon, lat):
        """The fences near lon, lat: gathered in a worker thread, once for every page
        (those within a quarter of ``near_m`` of the last gathering share it)."""
        have = self._near
        if have is not None and short_distance_m((have[1], have[0]), (lat, lon)) <= self.near_m / 4:
            return have[:2], have[2]
        if self._near_task is None or self._near_task.done():
            self._near_task = asyncio.ensure_future(
                asyncio.to_thread(self._around, self.near_records, lon, lat)
            )
            self._near_task.add_done_callback(lambda t, at=(lon, lat): self._keep_near(t, at))
        await asyncio.shield(self._near_task)
        have = self._near
        return have[:2], have[2]

    def _around(self, records, lon, lat) -> str:
        """The fences near lon, lat (in a worker thread), indexed again first when a live
        source changed them."""
        if records is not self.near.records:
            self.near = NearFences(records)
        return self.near.around(lon, lat, self.near_m)

    def _keep_near(self, task, at) -> None:
        if not task.cancelled() and task.exception() is None:
            self._near = (*at, task.result())
