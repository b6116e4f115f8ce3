"""The live map's web server (aiohttp), on the monitor's own event loop: ``GET /`` is the page,
``GET /ws`` the WebSocket that pushes what :class:`~alphafence.livemap.observer.LiveMap` keeps.

Safe by default: it binds to 127.0.0.1 unless told otherwise; on any other address every
request needs the token printed at start (``?token=``; without it: 403); it is read-only
(GET only, and nothing a page sends is read: no route reaches the vehicle); a WebSocket must
come from the server's own page (its ``Origin`` is the server's host) and, on 127.0.0.1, name
a loopback host (no other site's page, nor a DNS name rebound to 127.0.0.1, can read it).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import secrets
import socket
from dataclasses import dataclass
from urllib.parse import urlsplit

from alphafence.errors import InputError

DEFAULT_HOST = "127.0.0.1"
LOOPBACK_NAMES = {"localhost", "127.0.0.1", "::1"}
# a page's socket buffers at most this in the kernel (Linux doubles it), not the megabytes
# it grows to on its own: with the WebSocket writer's own 64 kB, what a vanished page holds
PAGE_SNDBUF = 16384
PAGE_BUFFER_MAX = 65536  # unsent bytes a page may have before it must catch up (or be dropped)
DRAIN_POLL_S = 0.05
CLOSE_TIMEOUT_S = 1.0  # a page being dropped gets this long to take the closing frame
NO_CACHE = {
    "Cache-Control": "no-store",
    "Referrer-Policy": "no-referrer",  # the token is in the URL
    "X-Content-Type-Options": "nosniff",
}


def parse_address(text: str, flag: str = "--map-server") -> tuple:
    """``HOST:PORT``, ``[IPv6]:PORT`` or ``PORT`` (on 127.0.0.1) -> ``(host, port)``.

    Examples
    --------
    >>> parse_address("8765"), parse_address("0.0.0.0:80"), parse_address("[::1]:0")
    (('127.0.0.1', 8765), ('0.0.0.0', 80), ('::1', 0))
    """
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = DEFAULT_HOST, text
    host = host.strip("[]") or DEFAULT_HOST
    if not port.isdigit() or int(port) > 65535:
        raise InputError(f"{flag} {text}", "give HOST:PORT (a port 0-65535; 0 picks a free one)")
    return host, int(port)


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this computer only (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass
class MapServer:
    """A running live map server.

    Attributes
    ----------
    url : str
        The page's address (with ``?token=`` when one is needed).
    host : str
    port : int
        The port bound (the one picked when 0 was asked for).
    token : str or None
        Needed by every request when not on a loopback address.
    runner : aiohttp.web.AppRunner
    """

    url: str
    host: str
    port: int
    token: str | None
    runner: object
    pages: set

    async def close(self) -> None:
        """Stop serving and drop every page."""
        for transport in list(self.pages):
            transport.abort()
        await self.runner.cleanup()


async def start_map_server(livemap, host=DEFAULT_HOST, port=0, page=None, token=None):
    """Serve ``livemap`` on ``host:port`` (on the running event loop).

    Parameters
    ----------
    livemap : LiveMap
        What the pages show.
    host : str
        Where to listen (default 127.0.0.1: this computer only).
    port : int
        0 picks a free port.
    page : str, optional
        The page's HTML (default :func:`alphafence.livemap.page.live_page`).
    token : str, optional
        Needed off loopback (a random one, ``secrets.token_urlsafe``, if not given); on a
        loopback address, needed only if given.

    Returns
    -------
    MapServer
    """
    from aiohttp import web

    loopback = is_loopback(host)
    pages = set()  # the open WebSockets' transports
    if token is None and not loopback:
        token = secrets.token_urlsafe(24)
    if page is None:
        from alphafence.livemap.page import live_page

        page = live_page()

    @web.middleware
    async def guard(request, handler):
        if token is not None:
            given = request.query.get("token", "")
            if not secrets.compare_digest(given.encode(), token.encode()):
                raise web.HTTPForbidden(text="a token is needed: open the URL printed at start\n")
        if loopback and _hostname(request.host) not in LOOPBACK_NAMES:
            raise web.HTTPForbidden(text="not a loopback host name\n")
        response = await handler(request)
        response.headers.update(NO_CACHE)
        return response

    async def no_icon(request):  # the browser asks for one
        return web.Response(status=204)

    async def index(request):
        return web.Response(text=page, content_type="text/html", charset="utf-8")

    async def live_socket(request):
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.host:
            raise web.HTTPForbidden(text="a page of another site\n")
        ws = web.WebSocketResponse(heartbeat=10.0, timeout=CLOSE_TIMEOUT_S, max_msg_size=4096)
        await ws.prepare(request)
        transport = request.transport
        pages.add(transport)
        sock = transport.get_extra_info("socket") if transport is not None else None
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, PAGE_SNDBUF)
        client = livemap.connect()
        ignore = asyncio.ensure_future(_ignore_incoming(ws))  # pings, closing; nothing read
        serving = asyncio.ensure_future(livemap.serve(client, _sender(ws, transport)))
        try:
            await asyncio.wait({ignore, serving}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            livemap.disconnect(client)
            for task in (ignore, serving):
                task.cancel()
                with contextlib.suppress(BaseException):
                    await task
            try:
                await asyncio.wait_for(ws.close(), CLOSE_TIMEOUT_S)
            except (asyncio.TimeoutError, ConnectionError):
                if transport is not None:
                    transport.abort()
            pages.discard(transport)
        return ws

    app = web.Application(middlewares=[guard])
    app.router.add_get("/", index, allow_head=False)
    app.router.add_get("/ws", live_socket, allow_head=False)
    app.router.add_get("/favicon.ico", no_icon, allow_head=False)
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        where = f"--map-server {host}:{port}"
        raise InputError(where, f"cannot listen there ({exc.strerror})") from None
    bound = runner.addresses[0][1]
    shown = f"[{host}]" if ":" in host else host
    if host in ("0.0.0.0", "::"):  # every address: the page is at this computer's name
        shown = socket.gethostname()
    url = f"http://{shown}:{bound}/" + (f"?token={token}" if token else "")
    return MapServer(url, host, bound, token, runner, pages)


def _sender(ws, transport):
    """``ws.send_str`` that first waits while the page has more than ``PAGE_BUFFER_MAX``
    bytes unsent (the caller's deadline then drops it): what a page that does not read
    holds stays bounded, whatever the web library buffers."""

    async def send(text: str) -> None:
        while transport is not None and transport.get_write_buffer_size() > PAGE_BUFFER_MAX:
            if transport.is_closing():
                raise ConnectionResetError("the page has gone")
            await asyncio.sleep(DRAIN_POLL_S)
        await ws.send_str(text)

    return send


def _hostname(host_header: str) -> str:
    return urlsplit(f"//{host_header}").hostname or ""


async def _ignore_incoming(ws) -> None:
    """Read (and drop) what the page sends, so pings are answered and closing is seen."""
    async for _ in ws:
        pass


async def open_live_map(fences, address: str, say, flag: str = "--map-server", basemap=None):
    """The live map of ``fences`` served at ``address`` (``HOST:PORT``), its URL said.

    Parameters
    ----------
    fences : FenceSet
        The full-resolution fences.
    address : str
        ``HOST:PORT`` (:func:`parse_address`).
    say : callable
        Called with the lines to print (the URL, the token's use).
    flag : str
        The option's name, for errors.
    basemap : dict, optional
        Drawn beneath (:func:`alphafence.plots.osm_basemap.osm_basemap`).

    Returns
    -------
    (LiveMap, MapServer)
        Add the LiveMap to the monitor's observers; close the server when done.
    """
    from alphafence.livemap.observer import LiveMap

    host, port = parse_address(address, flag)
    livemap = LiveMap(fences, basemap=basemap)
    server = await start_map_server(livemap, host, port)
    say(f"live map: {server.url}")
    if server.token:
        say(
            f"live map: on {host}, not this computer only: every request needs the token in "
            "that URL (read-only: nothing can be sent to the vehicle from the page)"
        )
    return livemap, server
