"""A reverse proxy on loopback that makes a real OGC API server misbehave on demand.

It forwards every GET to the upstream server (pygeoapi), rewriting the upstream's address in
the body (so ``next`` links come back through it), and then does what :attr:`FaultProxy.fault`
says: answer a status, wait, cut the body short, pad it, ask for a token, shift its ``Date``,
answer an empty collection, fail from the n-th page on, add malformed features, or answer
conditional requests with an ``ETag``. Started and stopped by the test, in its event loop.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
from datetime import datetime, timedelta, timezone
from email.utils import format_datetime


class FaultProxy:
    """Forward to ``upstream`` (``http://127.0.0.1:PORT``); :attr:`url` is the proxy's.

    Attributes
    ----------
    fault : dict
        What to do now: ``status`` (int), ``delay_s``, ``truncate`` (True), ``pad_bytes``,
        ``token`` (the one accepted), ``date_offset_s``, ``empty`` (True), ``fail_from_page``
        (1-based), ``extra_features`` (list), ``html`` (True), ``etag`` (True).
    requests : list of str
        Every path and query asked, in order.
    """

    def __init__(self, upstream: str):
        self.upstream = upstream.rstrip("/")
        self.fault: dict = {}
        self.requests: list = []
        self.url = None
        self._runner = None

    async def start(self, ssl_context=None) -> FaultProxy:
        """Listen on a free loopback port (HTTPS with ``ssl_context``)."""
        from aiohttp import web

        app = web.Application()
        app.router.add_get("/{tail:.*}", self._handle)
        self._runner = web.AppRunner(app)
        await self._runner.setup()
        site = web.TCPSite(self._runner, "127.0.0.1", 0, ssl_context=ssl_context)
        await site.start()
        port = site._server.sockets[0].getsockname()[1]
        self.url = f"{'https' if ssl_context else 'http'}://127.0.0.1:{port}"
        return self

    async def stop(self) -> None:
        if self._runner is not None:
            await self._runner.cleanup()

    async def _handle(self, request):
        import aiohttp
        from aiohttp import web

        f = self.fault
        self.requests.append(request.path_qs)
        offset, limit = int(request.query.get("offset", 0)), int(request.query.get("limit", 10))
        page = 1 + offset // max(1, limit)
        if f.get("delay_s"):
            await asyncio.sleep(f["delay_s"])
        if f.get("token") and request.headers.get("Authorization") != f"Bearer {f['token']}":
            return web.Response(status=401, text='{"code": "Unauthorized"}')
        if f.get("status"):
            return web.Response(status=f["status"], text="upstream trouble")
        if f.get("fail_from_page") and page >= f["fail_from_page"]:
            return web.Response(status=503, text="overloaded")
        if f.get("html"):
            return web.Response(text="<html>login</html>", content_type="text/html")
        async with aiohttp.ClientSession() as http:
            async with http.get(self.upstream + request.path_qs) as resp:
                body, status = await resp.read(), resp.status
        text = body.decode().replace(self.upstream, self.url)
        if status == 200 and ("/items" in request.path):
            doc = json.loads(text)
            if f.get("empty"):
                doc["features"], doc["numberMatched"], doc["links"] = [], 0, []
            extra = list(f.get("extra_features", [])) if page == 1 else []  # on the first page
            doc["features"] = list(doc.get("features", [])) + extra
            if "numberReturned" in doc:  # the counts kept true: a server that lies about
                doc["numberReturned"] = len(doc["features"])  # them gives a partial answer
            if extra and "numberMatched" in doc:
                doc["numberMatched"] += len(extra)
            if f.get("pad_bytes"):
                doc["padding"] = "x" * f["pad_bytes"]
            text = json.dumps(doc)
        headers = {"Content-Type": "application/geo+json"}
        when = datetime.now(timezone.utc) + timedelta(seconds=f.get("date_offset_s", 0.0))
        headers["Date"] = format_datetime(when, usegmt=True)
        if f.get("etag"):  # of the features, not of the answer's timeStamp
            data = json.dumps(json.loads(text).get("features"), sort_keys=True)
            tag = '"' + hashlib.sha256(data.encode()).hexdigest()[:16] + '"'
            headers["ETag"] = tag
            if request.headers.get("If-None-Match") == tag:
                return web.Response(status=304, headers=headers)
        if f.get("truncate"):
            text = text[: len(text) // 2]
        return web.Response(status=status, text=text, headers=headers)
