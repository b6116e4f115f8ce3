"""A synthetic country-scale database: an OSM extract's keep-out areas copied on a grid.

The restricted features of the extract whose rule kind is ``keep_out`` and whose geometry is
an area (133 on the Malta extract) are copied as often as it takes to reach N areas, each copy
shifted by a whole cell of a square grid whose cell is the areas' bounding box plus 5 %: copies
never overlap and never come within a join distance of each other, so every copy fences into
the same sites as the original. The grid is centred on the extract and stays within valid
latitudes (7,519 copies of Malta, 1,000,000 areas, span 29 degrees of longitude and 22 of
latitude). Each copy's features keep their tags and get a source of their own in ``"@id"``:
``"<source>/<copy>"`` (``"way/123/7"``), which the GeoJSON reader takes as the source.

Output is GeoJSON text sequences: one Feature per line (newline-delimited, ``.geojsonl``),
optionally each record after an RFC 8142 RS character (``.geojsons``), or one
FeatureCollection (``.geojson``). Output is deterministic: the same extract and N give the same
bytes. Coordinates are shifted with one vectorised ``shapely.transform`` and written with
``shapely.to_geojson`` on arrays, a few hundred copies at a time: 1,000,000 areas (478 MB) take
13 s and 0.2 GB.

python -m bench.synth_db 133000 /tmp/db.geojsonl
python -m bench.synth_db 133000 /tmp/db.geojson --collection --extract malta.osm.pbf
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import shapely

MALTA = (Path(__file__).parents[1] / "../shared/data/osm/malta-2018-08-27.osm.pbf").resolve()
FORMATS = {"lines": ".geojsonl", "rs": ".geojsons", "collection": ".geojson"}
GAP = 1.05  # grid cell / the areas' bounding box
CHUNK = 256  # copies per vectorised step
VERSION = 1  # in the cache's file names: bump when the output changes
MAX_LAT = 85.0


def keep_out_areas(extract):
    """The extract's restricted features of rule kind ``keep_out`` with an area geometry,
    sorted by source (the order copies are written in).

    Parameters
    ----------
    extract : str or Path
        Any database ``alphafence`` reads (an OSM extract).

    Returns
    -------
    list of alphafence.zones.features.Feature
    """
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    db = read_database([extract], load_rules())
    feats = [f for f in db.features if f.kind == "keep_out" and f.geomtype == "area"]
    if not feats:
        raise ValueError(f"{extract}: no keep-out areas to copy")
    return sorted(feats, key=lambda f: f.source)


def grid_offsets(copies, bounds):
    """The (dx, dy) shift in degrees of each copy: a square grid of cells the size of
    ``bounds`` (minx, miny, maxx, maxy) plus 5 %, centred on the original.

    Parameters
    ----------
    copies : int
    bounds : sequence of float

    Returns
    -------
    numpy.ndarray
        Shape (copies, 2).

    Raises
    ------
    ValueError
        The grid would reach beyond latitude 85 or longitude 180.

    Examples
    --------
    >>> grid_offsets(4, (0.0, 0.0, 1.0, 1.0)).tolist()
    [[-1.05, -1.05], [0.0, -1.05], [-1.05, 0.0], [0.0, 0.0]]
    """
    minx, miny, maxx, maxy = bounds
    cell = np.array([(maxx - minx) * GAP, (maxy - miny) * GAP])
    side = int(np.ceil(np.sqrt(copies)))
    rows = -(-copies // side)
    c = np.arange(copies)
    offsets = np.round(np.column_stack([c % side - side // 2, c // side - rows // 2]) * cell, 7)
    lo = np.array([minx, miny]) + offsets.min(axis=0)
    hi = np.array([maxx, maxy]) + offsets.max(axis=0)
    if lo[1] < -MAX_LAT or hi[1] > MAX_LAT or lo[0] < -180 or hi[0] > 180:
        raise ValueError(
            f"{copies} copies on a {side}x{rows} grid reach {lo.round(1)}..{hi.round(1)} (lon, lat)"
        )
    return offsets


def _shifter(shift):
    """A transform adding ``shift`` to each coordinate, rounded to 1e-7 degrees (OSM's
    precision: the offsets are whole multiples of it, so a copy is an exact translation)."""
    return lambda xy: np.round(xy + shift, 7)


def _heads(feats, rs):
    """Per base feature, the text of its record up to the copy number in its ``@id``, and
    what follows the copy number up to the geometry."""
    heads, tails = [], []
    for f in feats:
        props = {k: v for k, v in f.tags.items() if k not in ("@id", "id")}
        rest = json.dumps(props, ensure_ascii=False, sort_keys=True)[1:]  # "...}" or "}"
        src = json.dumps(f.source, ensure_ascii=False)[1:-1]
        heads.append(f'{rs}{{"type":"Feature","properties":{{"@id":"{src}/')
        tails.append('"' + (", " + rest if rest != "}" else "}") + ',"geometry":')
    return heads, tails


def write_database(extract, n, out, fmt="lines"):
    """Write ``n`` keep-out areas copied from ``extract`` on a grid (see the module).

    Parameters
    ----------
    extract : str or Path
    n : int
        Areas to write (the last copy may be partial).
    out : str or Path
        Written through a temporary file beside it, then renamed.
    fmt : {"lines", "rs", "collection"}
        One Feature per line, the same after an RS character (RFC 8142), or one
        FeatureCollection.

    Returns
    -------
    dict
        ``areas``, ``copies``, ``grid`` (columns, rows), ``bounds`` (of the whole database) and
        ``seconds``.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format {fmt!r}: expected one of {', '.join(FORMATS)}")
    t0 = time.perf_counter()
    feats = keep_out_areas(extract)
    base = np.array([f.geometry for f in feats], dtype=object)
    per_geom = shapely.get_num_coordinates(base)
    offsets = grid_offsets(-(-n // len(feats)), shapely.total_bounds(base))
    heads, tails = _heads(feats, "\x1e" if fmt == "rs" else "")
    sep = ",\n" if fmt == "collection" else "\n"
    out = Path(out)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    written = 0
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            if fmt == "collection":
                fh.write('{"type":"FeatureCollection","features":[\n')
            for start in range(0, len(offsets), CHUNK):
                block = offsets[start : start + CHUNK]
                count = min(len(block) * len(feats), n - written)
                geoms = np.tile(base, len(block))[:count]
                shift = np.repeat(
                    np.repeat(block, len(feats), axis=0)[:count],
                    per_geom[np.arange(count) % len(feats)],
                    axis=0,
                )
                text = shapely.to_geojson(shapely.transform(geoms, _shifter(shift)))
                idx = np.arange(count) % len(feats)
                copy = start + np.arange(count) // len(feats)
                lines = [
                    f"{heads[i]}{c}{tails[i]}{g}}}"
                    for i, c, g in zip(idx.tolist(), copy.tolist(), text.tolist())
                ]
                if written:
                    fh.write(sep)
                fh.write(sep.join(lines))
                written += count
            fh.write("\n]}\n" if fmt == "collection" else "\n")
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    side = int(np.ceil(np.sqrt(len(offsets))))
    minx, miny, maxx, maxy = shapely.total_bounds(base)
    lo, hi = offsets.min(axis=0), offsets.max(axis=0)
    return {
        "areas": written,
        "copies": len(offsets),
        "grid": (side, -(-len(offsets) // side)),
        "bounds": (minx + lo[0], miny + lo[1], maxx + hi[0], maxy + hi[1]),
        "seconds": time.perf_counter() - t0,
    }


def cache_dir() -> Path:
    """``$ALPHAFENCE_CACHE/bench``, default ``~/.cache/alphafence/bench`` (created)."""
    root = os.environ.get("ALPHAFENCE_CACHE") or Path.home() / ".cache" / "alphafence"
    path = Path(root) / "bench"
    path.mkdir(parents=True, exist_ok=True)
    return path


def cached_database(extract, n, fmt="lines"):
    """The path of ``n`` areas copied from ``extract``, generated once into :func:`cache_dir`
    and keyed by the extract's name, ``n``, the format and the generator's version.

    Returns
    -------
    (Path, float)
        The file, and the seconds spent generating it now (0.0 when it was cached).
    """
    name = Path(extract).name.split(".")[0]
    path = cache_dir() / f"{name}-keepout-{n}-v{VERSION}{FORMATS[fmt]}"
    if path.exists():
        return path, 0.0
    return path, write_database(extract, n, path, fmt)["seconds"]


def main(argv=None) -> int:
    """``python -m bench.synth_db N OUT``: write the database, print what was written."""
    p = argparse.ArgumentParser(prog="python -m bench.synth_db", description=__doc__.split("\n")[0])
    p.add_argument("n", type=int, metavar="N", help="areas to write")
    p.add_argument("out", metavar="OUT", help="output file")
    p.add_argument("--extract", default=str(MALTA), help="extract to copy (default Malta)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--collection", action="store_true", help="one FeatureCollection")
    group.add_argument("--rs", action="store_true", help="each record after RS (RFC 8142)")
    args = p.parse_args(argv)
    if args.n < 1:
        p.error("N must be at least 1")
    fmt = "collection" if args.collection else "rs" if args.rs else "lines"
    info = write_database(args.extract, args.n, args.out, fmt)
    print(
        f"{args.out}: {info['areas']} areas, {info['copies']} copies on a "
        f"{info['grid'][0]}x{info['grid'][1]} grid, lon/lat "
        + ",".join(f"{v:.2f}" for v in info["bounds"])
        + f", {info['seconds']:.1f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
