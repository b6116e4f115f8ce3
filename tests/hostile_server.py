"""An OGC API - Features server on loopback that turns against its client on demand.

It speaks HTTP/1.1 by hand over asyncio streams (in a thread of its own, so a synchronous
command-line test and an asynchronous monitor test can both use it), so it can do what a
framework would not let it: reset a connection mid-body, close early, never answer, trickle a
byte a second, send a gzip bomb, redirect to ``file:`` or another port, lie about its counts,
loop its ``next`` links, nest JSON 200,000 deep, date itself in the year 9999.

Served normally, ``/collections/zones/items?offset=K&limit=N`` is a page of :attr:`zones` with
``numberMatched``, ``numberReturned`` and a ``next`` link while more remain. :attr:`case` names
the misbehaviour (:data:`CASES`); :attr:`requests` records every request's path and headers.
"""

from __future__ import annotations

import asyncio
import copy
import json
import socket
import struct
import threading
import zlib
from datetime import datetime, timedelta, timezone
from email.utils import format_datetime
from urllib.parse import parse_qsl, urlsplit

CASES = {
    # zones lifted by an answer that is not complete
    "next-self": "a page whose next link points at the page itself",
    "next-back": "page 2's next link points back at page 1",
    "returned-more": "numberReturned larger than the features served, no numberMatched",
    "matched-fewer": "numberMatched smaller than the features served",
    "nan-vertex": "the first zone served with a NaN vertex",
    "all-malformed": "every feature malformed",
    # polling that stops
    "date-9999": "a Date header of Fri, 31 Dec 9999 23:59:59 GMT",
    "clock-far-off": "a Date two days ahead",
    "deep-body": "a body of JSON arrays nested 200,000 deep",
    "deep-coordinates": "the first zone's coordinates nested 500 deep",
    "nested-coordinates": "the first zone's coordinates nested 40 deep (the body within depth)",
    "not-modified-unasked": "HTTP 304 to a request without If-None-Match",
    "hostile-windows": "time windows of every wrong shape, and in the years 1 and 9999",
    # the operator's token
    "next-other-origin": "a next link to another port of this host",
    "next-file": "a next link to file:///etc/passwd",
    "redirect-other-port": "HTTP 302 to another port of this host",
    "redirect-file": "HTTP 302 to file:///etc/passwd",
    "redirect-data": "HTTP 302 to a data: URL",
    "redirect-loop": "HTTP 302 to itself",
    # memory
    "huge-pages": "pages padded to `pad` bytes each, 20 of them",
    "many-features": "`extra` copies of the zones served",
    # what a network does
    "reset": "the connection reset mid-body",
    "early-close": "the connection closed before the body's Content-Length",
    "silent": "a connection accepted and never answered",
    "trickle": "one byte a second",
    "gzip-bomb": "a gzip body that inflates to 64 MiB",
    "html": "HTML with a 200",
    "wrong-type": "XML with a 200",
    "not-collection": "a GeoJSON Feature, not a collection",
    "partial": "page 2 and later answer HTTP 503",
    "empty": "a complete answer with no feature",
}

BOMB_BYTES = 64 * 2**20  # twice the page bound, at 1,000:1
_BOMB = None


def gzip_bomb() -> bytes:
    """A gzip member of :data:`BOMB_BYTES` of spaces (valid JSON whitespace), made once."""
    global _BOMB
    if _BOMB is None:
        packer = zlib.compressobj(9, zlib.DEFLATED, 31)
        block = b" " * 2**20
        _BOMB = b"".join(packer.compress(block) for _ in range(BOMB_BYTES // len(block)))
        _BOMB += packer.flush()
    return _BOMB


def nan_zone(zone) -> dict:
    """``zone`` with its first vertex's longitude NaN."""
    bad = copy.deepcopy(zone)
    bad["geometry"]["coordinates"][0][0][0] = float("nan")
    return bad


def deep_zone(zone, depth=500) -> dict:
    """``zone`` with its coordinates nested ``depth`` deep."""
    bad = copy.deepcopy(zone)
    coords = [14.5, 35.9]
    for _ in range(depth):
        coords = [coords]
    bad["geometry"]["coordinates"] = coords
    return bad


class HostileServer:
    """The server; :meth:`start` it, :meth:`stop` it (or use it as a context manager).

    Attributes
    ----------
    zones : list of dict
        The Features it serves.
    case : str or None
        The misbehaviour now (a key of :data:`CASES`), None for a good server.
    pad, extra : int
        ``huge-pages``' page size and ``many-features``' copies.
    other : str
        Another origin (``http://127.0.0.1:PORT``) the cross-origin cases lead to.
    requests : list of (str, dict)
        Each request's path and query, and its headers (lower-case names).
    """

    def __init__(self, zones=(), other="http://127.0.0.1:9"):
        self.zones = list(zones)
        self.case = None
        self.pad = 31 * 2**20
        self.extra = 0
        self.other = other
        self.requests = []
        self.url = None
        self._loop = None
        self._thread = None
        self._server = None
        self._hold = None

    def __enter__(self) -> HostileServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def collection(self) -> str:
        return f"{self.url}/collections/zones"

    def start(self) -> HostileServer:
        ready = threading.Event()

        def serve():
            self._loop = asyncio.new_event_loop()
            self._hold = asyncio.Event()

            async def up():
                self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
                port = self._server.sockets[0].getsockname()[1]
                self.url = f"http://127.0.0.1:{port}"
                ready.set()

            self._loop.run_until_complete(up())
            self._loop.run_forever()

        self._thread = threading.Thread(target=serve, name="hostile-server", daemon=True)
        self._thread.start()
        ready.wait()
        return self

    def stop(self) -> None:
        async def down():
            self._hold.set()
            self._server.close()

        asyncio.run_coroutine_threadsafe(down(), self._loop).result()
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join()

    def authorized(self) -> list:
        """The requests that carried an ``Authorization`` header."""
        return [path for path, headers in self.requests if "authorization" in headers]

    async def _serve(self, reader, writer) -> None:
        try:
            head = await reader.readuntil(b"\r\n\r\n")
        except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError):
            writer.close()
            return
        lines = head.decode("latin-1").split("\r\n")
        target = lines[0].split(" ")[1]
        headers = {}
        for line in lines[1:]:
            if ":" in line:
                name, value = line.split(":", 1)
                headers[name.strip().lower()] = value.strip()
        self.requests.append((target, headers))
        try:
            await self._answer(writer, target, headers)
        except (ConnectionError, OSError):
            pass
        finally:
            if not writer.is_closing():
                writer.close()

    async def _answer(self, writer, target, headers) -> None:
        case = self.case
        parts = urlsplit(target)
        query = dict(parse_qsl(parts.query))
        offset, limit = int(query.get("offset", 0)), int(query.get("limit", 10))
        page = 1 + offset // max(1, limit)
        if case == "silent":
            await self._hold.wait()
            return
        if case and case.startswith("redirect-"):
            where = {"redirect-other-port": f"{self.other}{parts.path}",
                     "redirect-file": "file:///etc/passwd",
                     "redirect-data": "data:application/json,%7B%7D",
                     "redirect-loop": target}[case]  # fmt: skip
            await self._send(writer, 302, b"", {"Location": where})
            return
        if case == "not-modified-unasked":
            await self._send(writer, 304, b"", {})
            return
        if case == "partial" and page >= 2:
            await self._send(writer, 503, b"overloaded", {"Content-Type": "text/plain"})
            return
        if case == "html":
            await self._send(writer, 200, b"<html>login</html>", {"Content-Type": "text/html"})
            return
        if case == "wrong-type":
            body = b"<FeatureCollection/>"
            await self._send(writer, 200, body, {"Content-Type": "application/xml"})
            return
        if case == "deep-body":
            await self._send(writer, 200, b"[" * 200_000 + b"]" * 200_000, {})
            return
        if case == "gzip-bomb":
            await self._send(writer, 200, gzip_bomb(), {"Content-Encoding": "gzip"})
            return
        body = json.dumps(self._page(case, parts.path, offset, limit, page)).encode()
        extra = {}
        if case == "date-9999":
            extra["Date"] = "Fri, 31 Dec 9999 23:59:59 GMT"
        elif case == "clock-far-off":
            ahead = datetime.now(timezone.utc) + timedelta(days=2)
            extra["Date"] = format_datetime(ahead, usegmt=True)
        if case == "reset":
            await self._send(writer, 200, body, extra, cut=len(body) // 2, reset=True)
        elif case == "early-close":
            await self._send(writer, 200, body, extra, cut=len(body) // 2)
        elif case == "trickle":
            await self._send(writer, 200, body, extra, trickle=True)
        else:
            await self._send(writer, 200, body, extra)

    def _page(self, case, path, offset, limit, page) -> dict:
        zones = list(self.zones)
        if case == "empty":
            zones = []
        if case == "many-features":
            zones = zones + [dict(z, id=f"{z['id']}-{k}") for k in range(self.extra) for z in zones]
        if case == "nan-vertex" and zones:
            zones[0] = nan_zone(zones[0])
        if case == "deep-coordinates" and zones:
            zones[0] = deep_zone(zones[0])
        if case == "nested-coordinates" and zones:
            zones[0] = deep_zone(zones[0], 40)
        if case == "hostile-windows":
            shapes = [5, "always", [7], [{"schedule": 7}], [{"schedule": [{"day": 3}]}],
                      [{"startDateTime": "0001-01-01T00:00:00Z",
                        "endDateTime": "9999-12-31T23:59:59Z"}]]  # fmt: skip
            zones = [copy.deepcopy(z) for z in zones]
            for k, z in enumerate(zones):
                z["properties"]["limitedApplicability"] = shapes[k % len(shapes)]
        if case == "all-malformed":
            zones = [nan_zone(z) for z in zones]
        if case == "huge-pages":
            zones, pages = zones[:1], 20
        served = zones[offset : offset + limit]
        doc = {"type": "FeatureCollection", "features": served,
               "numberMatched": len(zones), "numberReturned": len(served), "links": []}  # fmt: skip
        more = offset + limit < len(zones)
        nxt = f"{path}?offset={offset + limit}&limit={limit}"
        if case == "huge-pages":
            doc["padding"] = "x" * self.pad
            more = page < pages
            doc.pop("numberMatched")
        if case == "returned-more":
            doc.pop("numberMatched")
            doc["numberReturned"] = len(served) + 5
        if case == "matched-fewer":
            doc["numberMatched"] = max(0, len(zones) - 1)
        if case == "next-self":
            more, nxt = True, f"{path}?offset={offset}&limit={limit}"
        if case == "next-back":  # page 2 (empty when one page holds all) leads back
            more = True
            if page >= 2:
                nxt = f"{path}?offset=0&limit={limit}"
        if case == "next-other-origin":
            more, nxt = True, f"{self.other}{path}?offset={offset + limit}&limit={limit}"
        if case == "partial":  # a page 2, whatever the page size
            more = more or page == 1
        if case == "next-file":
            more, nxt = True, "file:///etc/passwd"
        if case == "not-collection":
            return served[0] if served else {"type": "Feature"}
        if more:
            doc["links"].append({"rel": "next", "type": "application/geo+json", "href": nxt})
        return doc

    async def _send(self, writer, status, body, headers, cut=None, reset=False, trickle=False):
        head = {"Content-Type": "application/geo+json", "Content-Length": str(len(body)),
                "Connection": "close",
                "Date": format_datetime(datetime.now(timezone.utc), usegmt=True)}  # fmt: skip
        head.update(headers)
        reason = {200: "OK", 302: "Found", 304: "Not Modified", 503: "Service Unavailable"}
        text = f"HTTP/1.1 {status} {reason.get(status, 'X')}\r\n"
        text += "".join(f"{k}: {v}\r\n" for k, v in head.items()) + "\r\n"
        writer.write(text.encode("latin-1"))
        if trickle:
            for k in range(len(body)):
                writer.write(body[k : k + 1])
                await writer.drain()
                try:
                    await asyncio.wait_for(self._hold.wait(), 1.0)
                    return
                except asyncio.TimeoutError:
                    continue
        writer.write(body if cut is None else body[:cut])
        await writer.drain()
        if reset:  # an RST, not a FIN: SO_LINGER on, zero seconds
            sock = writer.get_extra_info("socket")
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            writer.transport.abort()
