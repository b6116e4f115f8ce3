"""Fences kept current: ``alphafence update`` against the whole rebuild, into PostGIS.

The extract is synthetic: Malta's keep-out areas copied on a grid (as ``synth_db`` copies them
for the scale bench), each copy's outer ring a closed way with the area's tags, written as an
``.osm.pbf`` by pyosmium and cached in ``$ALPHAFENCE_CACHE/bench``. A PostgreSQL cluster with
PostGIS is started on loopback (as the tests start it). Measured, each as a process pinned to
2 cores (wall time; peak memory of the process tree):

- the whole build into the PostGIS table, ``--jobs 2`` (the peer: what an update replaces);
- the same build with ``--store`` (the first build of a database kept current);
- one changed feature (one node of one area moved 3 m): ``alphafence update`` end to end,
  the process's start, the change read, its site rebuilt, the rows replaced, the median of 3:
  target under 2 s at 1,000,000 areas;
- a day of a country's changes: 300,000 changed objects, of which 5,000 touch restricted
  features (3,000 nodes of their outlines moved, 1,000 areas added, 500 deleted, 500 no longer
  restricted) and the rest are nodes no restricted feature uses: target under 60 s.
"""

from __future__ import annotations

import os
import random
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.cli_bench import _command
from bench.scale_bench import measure
from bench.synth_db import cache_dir, grid_offsets, keep_out_areas

SIZES = (133_000,)  # 1,000,000 on request: --update-sizes 133000,1000000
VERSION = 1
ONE_TARGET_S = 2.0
DAY_TARGET_S = 60.0
DAY = {"moved": 3000, "added": 1000, "deleted": 500, "untagged": 500, "background": 295_000}


def _rings(extract):
    """Each keep-out area's largest outer ring (lon, lat, closed) and its tags."""
    out = []
    for f in keep_out_areas(extract):
        g = f.geometry
        if g.geom_type == "MultiPolygon":
            g = max(g.geoms, key=lambda p: p.area)
        out.append((np.asarray(g.exterior.coords)[:-1], dict(f.tags)))
    return out


def write_extract(extract, n, out):
    """``n`` areas copied from ``extract`` as an OpenStreetMap extract ``out``; the layout
    (``rings``, ``offsets``) the changes are made from."""
    import osmium
    from osmium.osm import mutable

    rings = _rings(extract)
    pts = np.concatenate([r for r, _ in rings])
    bounds = (*pts.min(axis=0), *pts.max(axis=0))
    offsets = grid_offsets(-(-n // len(rings)), bounds)
    tmp = Path(out).with_name(f".{Path(out).name}.{os.getpid()}.tmp.osm.pbf")
    ways = []
    with osmium.SimpleWriter(str(tmp)) as w:
        nid = 1
        for k in range(n):
            ring, tags = rings[k % len(rings)]
            dx, dy = offsets[k // len(rings)]
            ids = list(range(nid, nid + len(ring)))
            for i, (lon, lat) in zip(ids, ring.tolist()):
                w.add_node(mutable.Node(id=i, location=(lon + dx, lat + dy), version=1))
            nid += len(ring)
            ways.append((ids, tags))
        for k, (ids, tags) in enumerate(ways, start=1):
            w.add_way(mutable.Way(id=k, nodes=[*ids, ids[0]], tags=tags, version=1))
    os.replace(tmp, out)
    return {"rings": rings, "offsets": offsets, "nodes": nid - 1, "ways": len(ways)}


def cached_extract(extract, n):
    """The cached extract of ``n`` areas and its layout (written on first use)."""
    path = cache_dir() / f"osm-areas-{n}-v{VERSION}.osm.pbf"
    if path.is_file():
        rings = _rings(extract)
        pts = np.concatenate([r for r, _ in rings])
        offsets = grid_offsets(-(-n // len(rings)), (*pts.min(axis=0), *pts.max(axis=0)))
        nodes = sum(len(rings[k % len(rings)][0]) for k in range(n))
        return path, {"rings": rings, "offsets": offsets, "nodes": nodes, "ways": n}
    return path, write_extract(extract, n, path)


def _node_ids(layout, k):
    """The node ids of area ``k`` (1-based way id ``k + 1``)."""
    rings = layout["rings"]
    sizes = np.array([len(rings[j % len(rings)][0]) for j in range(k + 1)])
    start = int(sizes[:-1].sum()) + 1
    return list(range(start, start + int(sizes[-1])))


def write_change(layout, path, moved=(), added=0, deleted=(), untagged=(), background=0, seed=0):
    """A change file: nodes of the areas ``moved`` shifted 3 m east, ``added`` new areas,
    the ways ``deleted`` removed, the ways ``untagged`` left with no restricted tag,
    ``background`` new nodes no way uses."""
    import osmium
    from osmium.osm import mutable

    rng = random.Random(seed)
    Path(path).unlink(missing_ok=True)  # pyosmium will not write over a file
    rings, offsets = layout["rings"], layout["offsets"]
    step = 3.0 / 111_320.0
    nid, wid = layout["nodes"] + 1, layout["ways"] + 1
    with osmium.SimpleWriter(str(path)) as w:
        nodes, ways = [], []
        for k in moved:
            ids = _node_ids(layout, k)
            ring = rings[k % len(rings)][0]
            dx, dy = offsets[k // len(rings)]
            i = rng.randrange(len(ids))
            lon, lat = ring[i]
            nodes.append(mutable.Node(id=ids[i], location=(lon + dx + step, lat + dy), version=2))
        for _ in range(added):
            ring, tags = rings[rng.randrange(len(rings))]
            dx, dy = offsets[rng.randrange(len(offsets))]
            dx, dy = dx + rng.uniform(-0.01, 0.01), dy + rng.uniform(-0.01, 0.01)
            ids = list(range(nid, nid + len(ring)))
            nid += len(ring)
            nodes += [mutable.Node(id=i, location=(lon + dx, lat + dy), version=1)
                      for i, (lon, lat) in zip(ids, ring.tolist())]  # fmt: skip
            ways.append(mutable.Way(id=wid, nodes=[*ids, ids[0]], tags=tags, version=1))
            wid += 1
        for _ in range(background):
            dx, dy = offsets[rng.randrange(len(offsets))]
            nodes.append(mutable.Node(id=nid, location=(14.5 + dx, 35.9 + dy), version=1))
            nid += 1
        for n in sorted(nodes, key=lambda n: n.id):
            w.add_node(n)
        for k in deleted:
            ways.append(mutable.Way(id=k + 1, nodes=[], version=2, visible=False))
        for k in untagged:
            ids = _node_ids(layout, k)
            ways.append(mutable.Way(id=k + 1, nodes=[*ids, ids[0]], tags={"building": "yes"},
                                    version=2))  # fmt: skip
        for way in sorted(ways, key=lambda x: x.id):
            w.add_way(way)


def _timed(argv):
    t0 = time.perf_counter()
    subprocess.run(_command() + argv, check=True, capture_output=True, text=True)
    return time.perf_counter() - t0


def run(extract, Row, console, sizes=SIZES):
    """The rows: for each size, the builds, one feature's update and a day's."""
    from tests.live_servers import PostGIS, postgis_missing

    if postgis_missing():
        return [Row("update: into PostGIS", f"not run: {postgis_missing()}", "-", "-", "-", False)]
    rows = []
    with tempfile.TemporaryDirectory(prefix="alphafence-update-bench-") as tmp:
        tmp = Path(tmp)
        pg = PostGIS(tmp / "pg").start()
        try:
            for n in sizes:
                rows += _size(extract, n, Row, console, pg, tmp)
        finally:
            pg.stop()
    return rows


def _size(extract, n, Row, console, pg, tmp):
    path, layout = cached_extract(extract, n)
    console.print(f"update bench: {n:,} areas ({path.name})")
    table, store = f"{pg.url}/public.f{n}", tmp / f"store-{n}.sqlite"
    cmd = _command()
    whole = measure([*cmd, "build", str(path), "-o", f"{pg.url}/public.w{n}", "--jobs", "2",
                     "-q"], 3600, 8e9)  # fmt: skip
    first = measure([*cmd, "build", str(path), "-o", table, "--store", str(store), "--jobs", "2",
                     "-q"], 3600, 8e9)  # fmt: skip
    for m in (whole, first):
        m["seconds"], m["ok"] = m["wall"], not (m["why"] or m["rc"])
        if not m["ok"]:
            raise RuntimeError(f"update bench: a build failed: {m['err'][0]}")
    middle = n // 2
    one = tmp / f"one-{n}.osc"
    write_change(layout, one, moved=[middle])
    argv = ["update", str(one), "--store", str(store), "-q"]
    ones = [_timed(argv) for _ in range(3)]
    day = tmp / f"day-{n}.osc"
    rng = random.Random(1)
    picks = rng.sample(range(n), DAY["moved"] + DAY["deleted"] + DAY["untagged"])
    moved = picks[: DAY["moved"]]
    deleted = picks[DAY["moved"] : DAY["moved"] + DAY["deleted"]]
    untagged = picks[DAY["moved"] + DAY["deleted"] :]
    write_change(layout, day, moved, DAY["added"], deleted, untagged, DAY["background"], seed=2)
    day_s = _timed(["update", str(day), "--store", str(store), "-q"])
    one_s = statistics.median(ones)
    size = f"{n:,} areas"
    return [
        Row(f"update: whole build into PostGIS, {size} (--jobs 2)", f"{whole['seconds']:.1f} s, "
            f"{whole['peak'] / 1e9:.2f} GB", "-", "-", "-", whole["ok"], whole["seconds"], "s"),
        Row(f"update: first build with --store, {size}", f"{first['seconds']:.1f} s, "
            f"{first['peak'] / 1e9:.2f} GB, store {store.stat().st_size / 1e9:.2f} GB",
            "-", f"whole build {whole['seconds']:.1f} s",
            f"{first['seconds'] / whole['seconds']:.2f}x", first["ok"], first["seconds"], "s"),
        Row(f"update: one changed feature, {size} (end to end, median of 3)",
            f"{one_s:.2f} s", f"< {ONE_TARGET_S:.0f} s", f"whole build {whole['seconds']:.1f} s",
            f"{one_s / whole['seconds']:.3f}x", one_s < ONE_TARGET_S, one_s, "s",
            whole["seconds"]),
        Row(f"update: a day's changes, {size} (300,000 objects, 5,000 restricted)",
            f"{day_s:.1f} s", f"< {DAY_TARGET_S:.0f} s", f"whole build {whole['seconds']:.1f} s",
            f"{day_s / whole['seconds']:.2f}x", day_s < DAY_TARGET_S, day_s, "s",
            whole["seconds"]),
    ]  # fmt: skip
