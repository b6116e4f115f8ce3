"""One request to a live source, as a good client makes it: a timeout and a bounded body,
retries with exponential backoff and full jitter for what may pass (refused, timeouts, 429,
5xx, a kept-alive connection the server had closed), and one line for each failure
(:class:`~alphafence.errors.SourceError`). :mod:`alphafence.sources.ogc` pages with it."""

from __future__ import annotations

import asyncio
import json
import random
import socket
from urllib.parse import urlsplit

from alphafence.errors import SourceError


async def get(http, options, url, conditional):
    """One request, retried with backoff and full jitter while a retry may help:
    ``(status, headers, parsed JSON or None, the body's bytes or None)``.

    Parameters
    ----------
    http : aiohttp.ClientSession
    options : SourceOptions
        Its timeout, size bound, retries and backoff.
    url : str
    conditional : dict
        ``If-None-Match`` / ``If-Modified-Since`` headers, or none.
    """
    tries, fresh = 0, False
    while True:
        try:
            return await _get_once(http, options, url, conditional)
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


async def _get_once(http, options, url, conditional):
    import aiohttp

    host = urlsplit(url).netloc
    try:
        timeout = aiohttp.ClientTimeout(total=options.timeout_s)
        async with http.get(url, headers=conditional, timeout=timeout) as resp:
            if resp.status == 304:
                return 304, resp.headers, None, None
            if resp.status >= 400:
                raise _status_error(url, resp.status)
            body = bytearray()
            async for chunk in resp.content.iter_chunked(65536):
                body += chunk
                if len(body) > options.max_bytes:
                    raise SourceError(
                        url, f"answer larger than {options.max_bytes / 2**20:.0f} MiB: not read"
                    )
            kind = resp.headers.get("Content-Type", "").split(";")[0].strip().lower()
            try:
                doc = json.loads(body)
            except ValueError:
                if kind and "json" not in kind:
                    raise SourceError(url, f"answer is not GeoJSON (content type {kind})") from None
                raise SourceError(url, "answer is not JSON (cut short or malformed)") from None
            return resp.status, resp.headers, doc, bytes(body)
    except SourceError:
        raise
    except (asyncio.TimeoutError, aiohttp.ServerTimeoutError):
        raise SourceError(url, f"no answer within {options.timeout_s:g} s", retry=True) from None
    except aiohttp.ClientConnectorCertificateError as exc:
        raise SourceError(
            url, f"TLS certificate of {host} not trusted ({exc.certificate_error}); "
            "give its CA with the CA file option", ) from None  # fmt: skip
    except aiohttp.ClientSSLError as exc:
        raise SourceError(url, f"TLS with {host} failed: {exc}") from None
    except aiohttp.ClientConnectorError as exc:
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
    _, _, _, raw = await get(http, options, url, {})
    return raw or b""
