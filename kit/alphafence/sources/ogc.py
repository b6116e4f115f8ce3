"""Asking an OGC API - Features collection for the zones in an area, as a good client asks.

``/collections/{id}/items`` with ``bbox`` and ``limit``, following the ``next`` links of
paging; conditional (``If-None-Match`` with the last ETag, ``If-Modified-Since``), compressed
(aiohttp asks for gzip and inflates), a bounded number of pages, a bearer token (services
behind OAuth2 give them), TLS verified against the system's or a given CA file; each request
with a timeout, a bounded body and retries (:mod:`alphafence.sources.request`). A URL that is not a collection (a plain GeoJSON file on a web
server) is fetched whole, once.

Every failure a user can meet is one line (:class:`~alphafence.errors.SourceError`). A failure
after the first page is not raised: the answer comes back *incomplete* with what was read and
why the rest was not; only a complete answer may ever remove a zone (the monitor's rule).
"""

from __future__ import annotations

import asyncio
import ssl
from dataclasses import dataclass, field
from datetime import datetime, timezone
from email.utils import parsedate_to_datetime
from urllib.parse import parse_qsl, urlencode, urljoin, urlsplit, urlunsplit

from alphafence.errors import SourceError
from alphafence.sources.request import get

ACCEPT = "application/geo+json, application/json;q=0.9"
PAGE_LIMIT = 500  # features asked per page
MAX_PAGES = 200  # pages followed in one answer (100,000 zones at the page size)
MAX_PAGE_BYTES = 32 * 2**20  # one page's body, inflated
TIMEOUT_S = 10.0  # one request, connection to last byte
RETRIES = 2  # more tries after the first, for what may pass
BACKOFF_S = 0.5  # the first retry's ceiling; doubled each time (full jitter below it)
TOKEN_ENV = "ALPHAFENCE_SOURCE_TOKEN"


@dataclass(frozen=True)
class SourceOptions:
    """How to ask a source.

    Attributes
    ----------
    url : str
        The collection (``https://host/collections/zones``; ``/items`` is added) or its items
        URL, or a plain GeoJSON document's URL.
    token : str, optional
        Sent as ``Authorization: Bearer <token>``.
    ca_file : str, optional
        Trust only these certificates (PEM) for TLS, not the system's.
    timeout_s, max_bytes, max_pages, limit, retries, backoff_s
        One request's time, one page's size, the pages of an answer, the features asked per
        page, the retries and the first backoff.
    """

    url: str
    token: str | None = None
    ca_file: str | None = None
    timeout_s: float = TIMEOUT_S
    max_bytes: int = MAX_PAGE_BYTES
    max_pages: int = MAX_PAGES
    limit: int = PAGE_LIMIT
    retries: int = RETRIES
    backoff_s: float = BACKOFF_S

    @property
    def items_url(self) -> str:
        """Where the features are: the collection's ``/items``, or the URL as given.

        Examples
        --------
        >>> SourceOptions("https://z.example/collections/uas").items_url
        'https://z.example/collections/uas/items'
        >>> SourceOptions("https://z.example/zones.geojson").items_url
        'https://z.example/zones.geojson'
        """
        parts = urlsplit(self.url)
        path = parts.path.rstrip("/")
        segments = path.split("/")
        if len(segments) >= 2 and segments[-2] == "collections":
            path += "/items"
        return urlunsplit(parts._replace(path=path))

    @property
    def paged(self) -> bool:
        """Whether the URL is an OGC API collection's items (asked by area, page by page)."""
        return self.items_url.rstrip("/").endswith("/items")


def read_token(path=None) -> str | None:
    """The bearer token: the first line of the file at ``path``, else the environment's
    ``ALPHAFENCE_SOURCE_TOKEN``, else None. A file that cannot be read is one line.

    Examples
    --------
    >>> import os; os.environ.pop(TOKEN_ENV, None) and None
    >>> read_token() is None
    True
    """
    import os

    if path:
        try:
            with open(path, encoding="utf-8") as f:
                token = f.readline().strip()
        except OSError as exc:
            raise SourceError(path, f"cannot read the token file: {exc.strerror or exc}") from None
        if not token:
            raise SourceError(path, "the token file is empty")
        return token
    return os.environ.get(TOKEN_ENV) or None


@dataclass
class Answer:
    """One answer of a source.

    Attributes
    ----------
    url : str
        The items URL asked.
    bbox : tuple or None
        The area asked (lon, lat), or None for everything.
    features : list of dict or None
        The GeoJSON Features read (None when ``not_modified``).
    complete : bool
        Every page was read (the answer may remove zones); False: ``error`` says why not.
    not_modified : bool
        The server said nothing changed since the last answer (HTTP 304).
    etag, last_modified : str or None
        The first page's validators, for the next conditional request.
    fetched_utc : str
        When it was asked (ISO 8601, UTC).
    server_skew_s : float or None
        The server's clock (its ``Date`` header) less this computer's, in seconds.
    pages : int
    error : SourceError or None
        Why the answer is incomplete.
    pages_raw : list of bytes
        Each page's body as it came (a worker process reads the features from these: bytes
        cross a process boundary for the price of a copy).
    """

    url: str
    bbox: tuple | None
    features: list | None
    complete: bool
    not_modified: bool = False
    etag: str | None = None
    last_modified: str | None = None
    fetched_utc: str = ""
    server_skew_s: float | None = None
    pages: int = 0
    error: SourceError | None = None
    seconds: float = 0.0
    bytes: int = 0
    matched: int | None = field(default=None)
    raw: bytes | None = None  # a whole document's bytes (not a collection's pages): to verify
    pages_raw: list = field(default_factory=list)  # each page's bytes, as they came

    def metadata(self) -> dict:
        """What an offline copy records of this answer (``build --source``)."""
        meta = {"url": self.url, "fetched_utc": self.fetched_utc, "complete": self.complete}
        for key in ("etag", "last_modified"):
            if getattr(self, key):
                meta[key] = getattr(self, key)
        if self.bbox is not None:
            meta["bbox"] = list(self.bbox)
        return meta


def ssl_context(ca_file=None):
    """TLS verified against the system's certificates, or only ``ca_file``'s."""
    try:
        return ssl.create_default_context(cafile=ca_file)
    except (OSError, ssl.SSLError) as exc:
        raise SourceError(ca_file, f"cannot read the CA file: {exc}") from None


def session(options: SourceOptions):
    """An aiohttp session for ``options`` (close it, or use it with ``async with``)."""
    import aiohttp

    connector = aiohttp.TCPConnector(ssl=ssl_context(options.ca_file), limit=4)
    timeout = aiohttp.ClientTimeout(total=options.timeout_s)
    headers = {"Accept": ACCEPT, "User-Agent": "alphafence"}
    if options.token:
        headers["Authorization"] = f"Bearer {options.token}"
    return aiohttp.ClientSession(connector=connector, timeout=timeout, headers=headers)


def _with_query(url: str, **params) -> str:
    parts = urlsplit(url)
    query = dict(parse_qsl(parts.query))
    query.update({k: v for k, v in params.items() if v is not None})
    return urlunsplit(parts._replace(query=urlencode(query, safe=",:/")))


async def fetch(http, options: SourceOptions, bbox=None, etag=None, last_modified=None) -> Answer:
    """Every zone the source holds in ``bbox`` (lon, lat), page by page.

    Parameters
    ----------
    http : aiohttp.ClientSession
        From :func:`session`.
    options : SourceOptions
    bbox : tuple, optional
        ``(min lon, min lat, max lon, max lat)``; None asks for everything.
    etag, last_modified : str, optional
        The last answer's validators: an unchanged source answers 304 (``not_modified``).

    Returns
    -------
    Answer
        Complete, not modified, or incomplete with its ``error`` (a page after the first
        failed, was cut short, or the pages ran over ``max_pages``).

    Raises
    ------
    SourceError
        The first page failed: one line saying how.
    """
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    fetched = datetime.now(timezone.utc)
    url = options.items_url
    first = url
    if options.paged:
        box = None if bbox is None else ",".join(f"{v:.7f}" for v in bbox)
        first = _with_query(url, bbox=box, limit=str(options.limit))
    conditional = {}
    if etag:
        conditional["If-None-Match"] = etag
    if last_modified:
        conditional["If-Modified-Since"] = last_modified
    asked = None if bbox is None or not options.paged else tuple(bbox)  # a document: all of it
    answer = Answer(url, asked, [], True,
                    fetched_utc=fetched.isoformat(timespec="milliseconds").replace("+00:00", "Z"))  # fmt: skip
    page_url, seen = first, set()
    while page_url is not None:
        try:
            status, headers, doc, raw = await get(http, options, page_url, conditional)
            size = len(raw or b"")
        except SourceError as exc:
            if answer.pages == 0:
                raise
            answer.complete, answer.error = False, exc
            break
        answer.pages += 1
        answer.bytes += size
        if answer.pages == 1:
            answer.etag, answer.last_modified = headers.get("ETag"), headers.get("Last-Modified")
            answer.server_skew_s = _skew(headers.get("Date"), fetched)
            if status == 304:
                answer.not_modified, answer.features = True, None
                break
        conditional = {}
        if not options.paged:
            answer.raw = raw
        answer.pages_raw.append(raw)
        features, next_url, matched = _page(options, page_url, doc)
        answer.features.extend(features)
        if answer.pages == 1 and matched is not None:
            answer.matched = matched
        seen.add(page_url)
        if next_url in seen:
            next_url = None  # a server whose next link loops: the pages so far are all
        if next_url is not None and answer.pages >= options.max_pages:
            answer.complete = False
            answer.error = SourceError(
                url, f"more than {options.max_pages} pages: the rest was not read"
            )
            break
        page_url = next_url
    if answer.complete and answer.matched is not None and len(answer.features) < answer.matched:
        answer.complete = False
        answer.error = SourceError(
            url, f"{len(answer.features)} features read of the {answer.matched} it matched"
        )
    answer.seconds = loop.time() - t0
    return answer


def _skew(date_header, fetched) -> float | None:
    if not date_header:
        return None
    try:
        server = parsedate_to_datetime(date_header)
    except (TypeError, ValueError):
        return None
    if server.tzinfo is None:
        server = server.replace(tzinfo=timezone.utc)
    return (server - fetched).total_seconds()


def _page(options, page_url, doc):
    """The features of one page, its ``next`` link and ``numberMatched``."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        what = doc.get("type") if isinstance(doc, dict) else type(doc).__name__
        raise SourceError(page_url, f"answer is not a GeoJSON FeatureCollection (a {what})")
    features = doc.get("features")
    if not isinstance(features, list):
        raise SourceError(page_url, "answer's FeatureCollection has no 'features' list")
    next_url = None
    if options.paged:
        for link in doc.get("links") or []:
            if isinstance(link, dict) and link.get("rel") == "next" and link.get("href"):
                next_url = urljoin(page_url, str(link["href"]))
                break
    matched = doc.get("numberMatched")
    matched = matched if isinstance(matched, int) and not isinstance(matched, bool) else None
    return features, next_url, matched
