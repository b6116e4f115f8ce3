"""A live source's answer at its budgets: what one costs in time and peak memory.

- At the byte budget: an answer of about 30 MiB (``MAX_ANSWER_BYTES`` is 32) over two pages,
  each 500 ED-318 zones of 1,300 vertices; at the feature budget: 20,000 zones
  (``MAX_FEATURES``) of 5 vertices over 40 pages of 500. Served from memory by a threaded
  ``http.server`` on loopback (a process of its own), asked by :func:`alphafence.sources.ogc.fetch` as ``build
  --source`` asks (the features kept) and as the monitor asks (only the pages' bytes kept: its
  worker reads them). Each run is a fresh spawned process: its peak resident memory (the
  kernel's high-water mark) less its resident memory before the answer, after the server's
  pages were made.
- Peer: the same pages' bytes parsed with ``json.loads`` from memory, in a fresh process the
  same way: the floor of reading that answer at all. Targets: the time within 2x the peer's;
  the peak within 1.5x the peer's as the monitor asks (one page parsed at a time), reported as
  build asks (it keeps every feature, as the peer does).
"""

from __future__ import annotations

import json
import math
import multiprocessing
import time

PAGE = 500


def _zone(k, vertices):
    lon0, lat0 = 14.30 + (k % 200) * 0.002, 35.80 + (k // 200) * 0.002
    ring = [[round(lon0 + 0.0008 * math.cos(2 * math.pi * j / vertices), 7),
             round(lat0 + 0.0008 * math.sin(2 * math.pi * j / vertices), 7)]
            for j in range(vertices)]  # fmt: skip
    ring.append(ring[0])
    return {"type": "Feature", "id": f"Z{k}", "geometry": {"type": "Polygon", "coordinates": [ring]},
            "properties": {"identifier": f"Z{k}", "name": f"closure {k}", "type": "PROHIBITED",
                           "zoneAuthority": [{"name": "bench"}]}}  # fmt: skip


def pages(count, vertices) -> list:
    """The answer's pages (bytes), ``PAGE`` zones each, ``next`` links between them."""
    out = []
    for p in range(math.ceil(count / PAGE)):
        feats = [_zone(k, vertices) for k in range(p * PAGE, min(count, (p + 1) * PAGE))]
        doc = {"type": "FeatureCollection", "features": feats, "numberMatched": count,
               "numberReturned": len(feats), "links": []}  # fmt: skip
        if (p + 1) * PAGE < count:
            doc["links"].append({"rel": "next", "href": f"/collections/z/items?page={p + 1}"})
        out.append(json.dumps(doc, separators=(",", ":")).encode())
    return out


def _rss_kb() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def _peak_kb() -> int:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _serve(bodies):
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
    from urllib.parse import parse_qs, urlsplit

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            page = int(parse_qs(urlsplit(self.path).query).get("page", ["0"])[0])
            body = bodies[page]
            self.send_response(200)
            self.send_header("Content-Type", "application/geo+json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *a):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _server(count, vertices, port, stop):
    """The answer's pages served from memory until ``stop`` is set (a process of its own)."""
    server = _serve(pages(count, vertices))
    port.put(server.server_address[1])
    stop.wait()


def _one(count, vertices, how, port, out):
    """In a fresh process: (seconds, peak memory increase in MiB, features read, MiB)."""
    import asyncio

    bodies = pages(count, vertices) if how == "peer" else None
    if how != "peer":
        import aiohttp  # noqa: F401 - imported before the baseline, as a monitor has it

        from alphafence.sources.ogc import SourceOptions, fetch, session
    base = _rss_kb()
    t0 = time.perf_counter()
    if how == "peer":
        docs = [json.loads(b) for b in bodies]
        n = sum(len(d["features"]) for d in docs)
    else:
        url = f"http://127.0.0.1:{port}/collections/z/items"
        options = SourceOptions(url, limit=PAGE)

        async def ask():
            async with session(options) as http:
                return await fetch(http, options, None, keep=how)

        answer = asyncio.run(ask())
        assert answer.complete, answer.error
        n = answer.count
    seconds = time.perf_counter() - t0
    size = sum(map(len, bodies)) if bodies else answer.bytes
    out.put((seconds, max(0, _peak_kb() - base) / 1024, n, size / 2**20))


def measure(count, vertices, how):
    """One run in a fresh process (the server, when asked over HTTP, in another)."""
    context = multiprocessing.get_context("spawn")
    out, port, stop = context.Queue(), context.Queue(), context.Event()
    server = None
    if how != "peer":
        server = context.Process(target=_server, args=(count, vertices, port, stop))
        server.start()
    proc = context.Process(
        target=_one, args=(count, vertices, how, port.get() if server else 0, out)
    )
    proc.start()
    result = out.get()
    proc.join()
    if server is not None:
        stop.set()
        server.join()
    return result


def run(Row) -> list:
    from alphafence.sources.ogc import MAX_ANSWER_BYTES, MAX_FEATURES

    rows = []
    cases = [(f"{MAX_ANSWER_BYTES / 2**20:.0f} MiB", 2 * PAGE, 1300),
             (f"{MAX_FEATURES:,} features", MAX_FEATURES, 5)]  # fmt: skip
    for label, count, vertices in cases:
        peer_s, peer_mb, _, size = measure(count, vertices, "peer")
        for how, what in (("raw", "as the monitor asks"), ("features", "as build asks")):
            s, mb, n, _ = measure(count, vertices, how)
            assert n == count
            rows.append(Row(f"source answer at the budget ({label}, {size:.0f} MiB), {what}: time",
                            f"{s:.2f} s", "<= 2x json.loads of its pages", f"json.loads {peer_s:.2f} s",
                            f"{s / peer_s:.2f}x", s <= 2 * peer_s, s, "s", peer_s))  # fmt: skip
            target = mb <= 1.5 * peer_mb if how == "raw" else True
            rows.append(Row(f"source answer at the budget ({label}, {size:.0f} MiB), {what}: peak memory",
                            f"{mb:.0f} MiB", "<= 1.5x json.loads of its pages" if how == "raw"
                            else "reported", f"json.loads {peer_mb:.0f} MiB",
                            f"{mb / peer_mb:.2f}x", target, mb, "MiB", peer_mb))  # fmt: skip
    return rows
