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
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

from alphafence.errors import SourceError
from alphafence.sources.request import follow, get, origin, server_skew

ACCEPT = "application/geo+json, application/json;q=0.9"
PAGE_LIMIT = 500  # features asked per page
MAX_PAGES = 200  # pages followed in one answer (100,000 zones at the page size)
MAX_PAGE_BYTES = 32 * 2**20  # one page's body, inflated
MAX_ANSWER_BYTES = 32 * 2**20  # every page of one answer, inflated
MAX_FEATURES = 20_000  # features in one answer
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
    max_answer_bytes, max_features : int
        One answer's budget, over all its pages: its bodies' bytes (inflated) and its
        features. An answer over either is incomplete.
    also_origins : tuple of str
        Origins besides the source's own (``https://host:port``) that its ``next`` links and
        redirects may lead to, the token with them; any other is refused.
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
    max_answer_bytes: int = MAX_ANSWER_BYTES
    max_features: int = MAX_FEATURES
    also_origins: tuple = ()

    @property
    def origins(self) -> tuple:
        """The origins the source may be asked at (and its token sent to): its own, then the
        ones named.

        Examples
        --------
        >>> o = SourceOptions("https://z.example/collections/uas", also_origins=("https://cdn.z",))
        >>> o.origins
        ('https://z.example:443', 'https://cdn.z:443')
        """
        return (origin(self.url), *(origin(o) for o in self.also_origins))

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
        The GeoJSON Features read (None when ``not_modified``; empty when only the pages'
        bytes were kept).
    complete : bool
        Every page was read, none twice, and the counts the server gave agree with the
        features read (the answer may remove zones); False: ``error`` says why not.
    count : int
        The features read.
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
    count: int = 0
    error: SourceError | None = None
    seconds: float = 0.0
    bytes: int = 0
    matched: int | None = field(default=None)
    raw: bytes | None = None  # a whole document's bytes (not a collection's pages): to verify
    pages_raw: list = field(default_factory=list)  # each page's bytes, as they came

    def __repr__(self) -> str:  # short: an answer holds megabytes (Python 3.11's asyncio.run
        # formats the result of its main task when it looks at SIGINT's handler)
        return (f"Answer({self.url!r}, complete={self.complete}, not_modified="
                f"{self.not_modified}, pages={self.pages}, count={self.count}, "
                f"bytes={self.bytes}, error={self.error!r})")  # fmt: skip

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
    headers = {"Accept": ACCEPT, "User-Agent": "alphafence"}  # the token: per request, by origin
    return aiohttp.ClientSession(connector=connector, timeout=timeout, headers=headers)


def _with_query(url: str, **params) -> str:
    parts = urlsplit(url)
    query = dict(parse_qsl(parts.query))
    query.update({k: v for k, v in params.items() if v is not None})
    return urlunsplit(parts._replace(query=urlencode(query, safe=",:/")))


async def fetch(
    http, options: SourceOptions, bbox=None, etag=None, last_modified=None, keep="features"
) -> Answer:
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
    keep : {"features", "raw"}
        Keep the features read (``Answer.features``), or only each page's bytes
        (``Answer.pages_raw``, for a worker process to read: one page parsed at a time here).

    Returns
    -------
    Answer
        Complete, not modified, or incomplete with its ``error``: a page after the first
        failed or was not a collection; a ``next`` link looped, or led to another origin or
        scheme; a page's ``numberReturned`` or the answer's ``numberMatched`` disagrees with
        the features read; the pages, bytes or features ran over their budget.

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
    page_url, seen = first, {}
    try:
        while page_url is not None:
            page_url = await _read_page(http, options, answer, page_url, conditional, seen, keep)
            conditional = {}
        _check_matched(answer)
    except _Incomplete as stop:
        answer.complete, answer.error = False, stop.error
    answer.seconds = loop.time() - t0
    return answer


class _Incomplete(Exception):
    """What stops an answer after its first page: it comes back incomplete."""

    def __init__(self, error):
        self.error = error


def _fail(answer, error):
    if answer.pages == 0:
        raise error
    raise _Incomplete(error)


async def _read_page(http, options, answer, page_url, conditional, seen, keep):
    """Ask one page and take it into ``answer``: the next page's URL, or None after the last."""
    left = options.max_answer_bytes - answer.bytes
    limit, over = options.max_bytes, None
    if left < limit:
        limit = left
        over = (f"answer larger than {options.max_answer_bytes / 2**20:g} MiB over "
                f"{answer.pages + 1} pages: the rest was not read")  # fmt: skip
    try:
        status, headers, doc, raw, answered = await get(
            http, options, page_url, conditional, limit, over
        )
    except SourceError as exc:
        _fail(answer, exc)
    answer.pages += 1
    answer.bytes += len(raw or b"")
    if answer.pages == 1:
        answer.etag, answer.last_modified = headers.get("ETag"), headers.get("Last-Modified")
        answer.server_skew_s = server_skew(headers.get("Date"), answer.fetched_utc)
    if status == 304:
        if answer.pages > 1:  # only the first page is asked conditionally
            _fail(answer, SourceError(page_url, "HTTP 304 to a page that was not conditional"))
        answer.not_modified, answer.features = True, None
        return None
    try:
        features, href, matched, returned = _page(options, answered, doc)
    except SourceError as exc:
        answer.pages -= 1  # not a page of the answer
        _fail(answer, exc)
    n = answer.pages
    seen[page_url] = seen[answered] = n
    if not options.paged:
        answer.raw = raw
    if keep == "raw":
        answer.pages_raw.append(raw)
    else:
        answer.features.extend(features)
    answer.count += len(features)
    if answer.matched is None and matched is not None:
        answer.matched = matched
    if returned is not None and returned != len(features):
        raise _Incomplete(SourceError(page_url, f"page {n} says numberReturned {returned} but "
                                      f"holds {len(features)} features"))  # fmt: skip
    if answer.count > options.max_features:
        raise _Incomplete(SourceError(answer.url, f"more than {options.max_features} features: "
                                      "the rest was not read"))  # fmt: skip
    if href is None:
        return None
    try:
        next_url = follow(options, answered, href, f"page {n}'s next link")
    except SourceError as exc:
        raise _Incomplete(exc) from None
    if next_url in seen:
        raise _Incomplete(SourceError(page_url, f"page {n}'s next link leads back to page "
                                      f"{seen[next_url]}: the pages loop"))  # fmt: skip
    if n >= options.max_pages:
        raise _Incomplete(SourceError(answer.url, f"more than {options.max_pages} pages: the "
                                      "rest was not read"))  # fmt: skip
    return next_url


def _check_matched(answer) -> None:
    if answer.matched is not None and not answer.not_modified and answer.count != answer.matched:
        raise _Incomplete(SourceError(answer.url, f"{answer.count} features read of the "
                                      f"{answer.matched} it matched"))  # fmt: skip


def _page(options, page_url, doc):
    """The features of one page, its ``next`` link (as served), ``numberMatched`` and
    ``numberReturned`` (None where not given as counts)."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        what = doc.get("type") if isinstance(doc, dict) else type(doc).__name__
        raise SourceError(
            page_url, f"answer is not a GeoJSON FeatureCollection (a {str(what)[:40]})"
        )
    features = doc.get("features")
    if not isinstance(features, list):
        raise SourceError(page_url, "answer's FeatureCollection has no 'features' list")
    href = None
    if options.paged:
        links = doc.get("links")
        for link in links if isinstance(links, list) else ():
            if isinstance(link, dict) and link.get("rel") == "next" and link.get("href"):
                href = link["href"]
                break
    return features, href, _count(doc.get("numberMatched")), _count(doc.get("numberReturned"))


def _count(value):
    return value if isinstance(value, int) and not isinstance(value, bool) and value >= 0 else None
