"""One request to a live source, as a good client makes it: a timeout and a bounded body,
retries with exponential backoff and full jitter for what may pass (refused, timeouts, 429,
5xx, a kept-alive connection the server had closed), and one line for each failure
(:class:`~alphafence.errors.SourceError`). :mod:`alphafence.sources.ogc` pages with it.

A server is not trusted with anything: the bearer token goes only to the source's own origin
(scheme, host and port) or one the user named; redirects are followed here, one by one, and
one to another origin or to a scheme that is not HTTP(S) is refused; a body is read up to its
byte budget, and its JSON nesting is measured before it is parsed (:func:`loads`), so that no
answer can make the parser recurse without bound.
"""

from __future__ import annotations

import asyncio
import json
import random
import re
import socket
from urllib.parse import urljoin, urlsplit

from alphafence.errors import SourceError

MAX_DEPTH = 64  # JSON nesting read (a MultiPolygon Feature in a collection needs 8)
MAX_REDIRECTS = 5
REDIRECTS = (301, 302, 303, 307, 308)
SCHEMES = ("http", "https")
_PORTS = {"http": 80, "https": 443}
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_NOT_BRACKETS = bytes(sorted(set(range(256)) - set(b"[]{}")))


def origin(url: str) -> str:
    """``scheme://host:port`` of ``url`` (the port written out), or ``""`` for a URL that is
    not HTTP(S).

    Examples
    --------
    >>> origin("https://Zones.example/collections/uas"), origin("http://127.0.0.1:8080/x")
    ('https://zones.example:443', 'http://127.0.0.1:8080')
    >>> origin("file:///etc/passwd")
    ''
    """
    try:
        parts = urlsplit(str(url))
        port = parts.port
    except ValueError:
        return ""
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES or not parts.hostname:
        return ""
    return f"{scheme}://{parts.hostname.lower()}:{port or _PORTS[scheme]}"


def follow(options, base: str, href, what: str) -> str:
    """``href`` (a ``next`` link, a redirect's ``Location``) resolved against ``base``, when the
    source may be asked there: an HTTP(S) URL of the source's own origin or of one the user
    named (:attr:`SourceOptions.origins`). Anything else is a SourceError that no retry helps.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> o = SimpleNamespace(origins=("https://z.example:443",))
    >>> follow(o, "https://z.example/items", "?offset=10", "next link")
    'https://z.example/items?offset=10'
    >>> follow(o, "https://z.example/items", "https://z.example:8443/items", "next link")
    Traceback (most recent call last):
    ...
    alphafence.errors.SourceError: https://z.example/items: next link to another origin \
(https://z.example:8443), not followed: the token and the zones are the source's own (allow it \
with --source-origin)
    """
    url = urljoin(base, str(href).strip())
    scheme = urlsplit(url).scheme.lower()
    if scheme not in SCHEMES:
        raise SourceError(base, f"{what} to a {scheme or 'schemeless'}: URL, not followed")
    there = origin(url)
    if there not in options.origins:
        raise SourceError(base, f"{what} to another origin ({there or url}), not followed: the "
                          "token and the zones are the source's own (allow it with "
                          "--source-origin)")  # fmt: skip
    return url


def nesting(body: bytes) -> int:
    """How deep ``body``'s JSON arrays and objects nest (brackets inside strings do not count),
    without parsing it: vectorised, so a hostile body costs no recursion.

    Examples
    --------
    >>> nesting(b'{"a": [[1, 2], "]]]"]}'), nesting(b'[' * 5000), nesting(b'"[\\\\"[["')
    (3, 5000, 0)
    """
    import numpy as np

    brackets = _STRING.sub(b"", bytes(body)).translate(None, _NOT_BRACKETS)
    if not brackets:
        return 0
    step = np.zeros(256, np.int8)
    step[list(b"[{")], step[list(b"]}")] = 1, -1
    return int(np.cumsum(step[np.frombuffer(brackets, np.uint8)], dtype=np.int64).max())


def loads(url: str, body: bytes, kind: str = ""):
    """``body``'s JSON, parsed when it nests at most :data:`MAX_DEPTH` deep; SourceError (one
    line) otherwise, or when it is not JSON (``kind``: its content type, named then)."""
    depth = nesting(body)
    if depth > MAX_DEPTH:
        raise SourceError(
            url, f"answer nested {depth} deep (at most {MAX_DEPTH} is read): not read"
        )
    try:
        return json.loads(body)
    except (ValueError, RecursionError):
        if kind and "json" not in kind:
            raise SourceError(url, f"answer is not GeoJSON (content type {kind})") from None
        raise SourceError(url, "answer is not JSON (cut short or malformed)") from None


async def get(http, options, url, conditional, max_bytes=None, over=None):
    """One request, retried with backoff and full jitter while a retry may help:
    ``(status, headers, parsed JSON or None, the body's bytes or None, the URL answered)``.

    Parameters
    ----------
    http : aiohttp.ClientSession
    options : SourceOptions
        Its timeout, size bound, retries, backoff, token and the origins it may go to.
    url : str
    conditional : dict
        ``If-None-Match`` / ``If-Modified-Since`` headers, or none.
    max_bytes : int, optional
        The body's bound (default: the options' page bound), and ``over``: what to say past it.
    """
    tries, fresh = 0, False
    while True:
        try:
            return await _get_once(http, options, url, conditional, max_bytes, over)
        except SourceError as exc:
            if getattr(exc, "stale", False) and not fresh:  # a kept-alive connection the
                fresh = True  # server had closed: asked again at once, on a new one
                continue
            if not exc.retry or tries >= options.retries:
                if tries:
                    raise SourceError(exc.url, f"{exc.message} (after {tries + 1} tries)") from None
                raise
        tries += 1
        await asyncio.sleep(random.uniform(0.0, options.backoff_s * 2 ** (tries - 1)))


async def _get_once(http, options, url, conditional, max_bytes, over):
    import aiohttp

    limit = options.max_bytes if max_bytes is None else max_bytes
    over = over or f"answer larger than {limit / 2**20:.0f} MiB: not read"
    asked = url
    try:
        timeout = aiohttp.ClientTimeout(total=options.timeout_s)
        for _ in range(MAX_REDIRECTS + 1):
            headers = dict(conditional)
            if options.token and origin(url) in options.origins:  # never to another origin
                headers["Authorization"] = f"Bearer {options.token}"
            async with http.get(url, headers=headers, timeout=timeout,
                                allow_redirects=False) as resp:  # fmt: skip
                if resp.status in REDIRECTS:
                    location = resp.headers.get("Location")
                    if not location:
                        raise SourceError(url, f"HTTP {resp.status} redirect without a Location")
                    url = follow(options, url, location, f"HTTP {resp.status} redirect")
                    continue
                if resp.status == 304:
                    if not conditional:
                        raise SourceError(url, "HTTP 304 Not Modified to a request that was "
                                          "not conditional: nothing to keep")  # fmt: skip
                    return 304, resp.headers, None, None, url
                if resp.status >= 400:
                    raise _status_error(url, resp.status)
                body = bytearray()
                async for chunk in resp.content.iter_chunked(65536):
                    body += chunk
                    if len(body) > limit:
                        raise SourceError(url, over)
                kind = resp.headers.get("Content-Type", "").split(";")[0].strip().lower()
                doc = loads(url, body, kind)
                return resp.status, resp.headers, doc, bytes(body), url
        raise SourceError(asked, f"more than {MAX_REDIRECTS} redirects: not followed")
    except SourceError:
        raise
    except (asyncio.TimeoutError, aiohttp.ServerTimeoutError):
        raise SourceError(url, f"no answer within {options.timeout_s:g} s", retry=True) from None
    except aiohttp.ClientConnectorCertificateError as exc:
        raise SourceError(
            url, f"TLS certificate of {urlsplit(url).netloc} not trusted "
            f"({exc.certificate_error}); give its CA with the CA file option", ) from None  # fmt: skip
    except aiohttp.ClientSSLError as exc:
        raise SourceError(url, f"TLS with {urlsplit(url).netloc} failed: {exc}") from None
    except aiohttp.ClientConnectorError as exc:
        host = urlsplit(url).netloc
        os_error = getattr(exc, "os_error", None)
        if isinstance(os_error, socket.gaierror):
            raise SourceError(url, f"cannot resolve host {exc.host!r}", retry=True) from None
        if isinstance(os_error, ConnectionRefusedError):
            raise SourceError(
                url, f"connection refused by {host} (is the server running?)", retry=True
            ) from None
        raise SourceError(url, f"cannot connect to {host}: {os_error or exc}", retry=True) from None
    except aiohttp.ServerDisconnectedError:
        error = SourceError(url, "the server closed the connection: answer cut short", retry=True)
        error.stale = True
        raise error from None
    except aiohttp.ClientPayloadError as exc:
        raise SourceError(url, f"answer cut short: {type(exc).__name__}", retry=True) from None
    except aiohttp.ClientError as exc:
        raise SourceError(url, f"request failed: {type(exc).__name__}: {exc}", retry=True) from None
    except (ValueError, UnicodeError) as exc:  # a URL or header aiohttp cannot take
        raise SourceError(url, f"request failed: {type(exc).__name__}: {exc}") from None


def _status_error(url, status) -> SourceError:
    """One line for an HTTP error status; whether to retry it."""
    if status == 401:
        return SourceError(url, "HTTP 401: the token is missing, expired or wrong")
    if status == 403:
        return SourceError(url, "HTTP 403: the token is not allowed to read this collection")
    if status == 404:
        return SourceError(url, "HTTP 404: no such collection (check /collections/{id})")
    if status == 429:
        return SourceError(url, "HTTP 429: too many requests", retry=True)
    if status >= 500:
        return SourceError(url, f"HTTP {status}: server error", retry=True)
    return SourceError(url, f"HTTP {status}: request refused")


async def fetch_bytes(http, options, url: str) -> bytes:
    """The body at ``url`` (a signature beside a document), asked as every request is:
    SourceError (one line) when it fails or is not JSON."""
    _, _, _, raw, _ = await get(http, options, url, {})
    return raw or b""


def server_skew(date_header, fetched_utc) -> float | None:
    """The server's ``Date`` less ``fetched_utc`` (ISO 8601), in seconds; None when there is
    no date, or none this computer can represent.

    Examples
    --------
    >>> server_skew("Mon, 07 Dec 2026 10:00:30 GMT", "2026-12-07T10:00:00.000Z")
    30.0
    >>> server_skew("Fri, 31 Dec 9999 23:59:59 GMT", "2026-12-07T10:00:00.000Z") > 2e11
    True
    """
    from datetime import datetime, timezone
    from email.utils import parsedate_to_datetime

    if not date_header:
        return None
    try:
        server = parsedate_to_datetime(date_header)
        if server.tzinfo is None:
            server = server.replace(tzinfo=timezone.utc)
        fetched = datetime.fromisoformat(fetched_utc.replace("Z", "+00:00"))
        return (server - fetched).total_seconds()
    except (TypeError, ValueError, OverflowError, IndexError):
        return None
