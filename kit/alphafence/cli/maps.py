"""What the verbs that draw an interactive map share: ``--map FILE.html``, ``--tiles`` and
``--tiles-attribution``, checked before any work, and the page written at the end."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from alphafence.errors import InputError


def add_map_options(p) -> None:
    """Add ``--map``, ``--tiles`` and ``--tiles-attribution`` to the verb's parser ``p``."""
    p.add_argument(
        "--map",
        metavar="FILE.html",
        help="also write an interactive map: one HTML file that opens with no network "
        "(Leaflet and the data inside; layers to switch, a click shows a fence's details)",
    )
    p.add_argument(
        "--tiles",
        metavar="URL-TEMPLATE",
        help="a basemap for --map: a tile URL template such as "
        "https://tile.example.org/{z}/{x}/{y}.png (the only thing the page then fetches; "
        "needs --tiles-attribution), or a local FILE.mbtiles whose tiles around the data go "
        "into the page (default: no basemap)",
    )
    p.add_argument(
        "--tiles-attribution",
        metavar="TEXT",
        help="the basemap's attribution, shown in the map's corner (the tile provider's terms "
        "say what it must be)",
    )


def _writable(path: Path) -> str | None:
    """Why ``path`` cannot be written, or None."""
    if path.is_dir():
        return "is a folder"
    folder = path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        return f"{folder} is not a folder"
    try:
        fd, tmp = tempfile.mkstemp(prefix=".alphafence-map.", dir=folder)
    except OSError as exc:
        return f"cannot write in {folder}: {exc.strerror or exc}"
    os.close(fd)
    os.unlink(tmp)
    return None


def check_map_args(args) -> None:
    """Refuse, before any work, a ``--map`` that cannot be written or is not ``.html``, and
    ``--tiles`` options that do not fit together.

    Raises
    ------
    InputError
        One line naming the option and what is wrong.
    """
    path = getattr(args, "map", None)
    tiles, attribution = getattr(args, "tiles", None), getattr(args, "tiles_attribution", None)
    if path is None:
        if tiles or attribution:
            raise InputError("--tiles", "a basemap is for --map FILE.html; give --map too")
        return
    if Path(path).suffix.lower() not in (".html", ".htm"):
        raise InputError("--map", f"{path}: the map is an HTML page; name it FILE.html")
    why = _writable(Path(path))
    if why:
        raise InputError("--map", f"{path} cannot be written: {why}")
    if attribution and not tiles:
        raise InputError("--tiles-attribution", "names a basemap's source; give --tiles too")
    if not tiles:
        return
    if tiles.lower().endswith(".mbtiles"):
        from alphafence.plots.mbtiles import check_mbtiles

        check_mbtiles(tiles)
        return
    if not tiles.startswith(("https://", "http://")) or not all(
        key in tiles for key in ("{z}", "{x}", "{y}")
    ):
        raise InputError(
            "--tiles",
            f"{tiles!r} is not a tile URL template like https://tile.example.org/{{z}}/{{x}}/{{y}}.png "
            "nor a .mbtiles file",
        )
    if not attribution:
        raise InputError(
            "--tiles", "a basemap needs --tiles-attribution TEXT (its provider's terms say what)"
        )


def map_tiles(args, bounds):
    """The page's ``tiles`` for ``--tiles`` (None without): the template and attribution, or
    an MBTiles file's tiles around ``bounds`` (``[[south, west], [north, east]]``)."""
    tiles = getattr(args, "tiles", None)
    if not tiles:
        return None
    if tiles.lower().endswith(".mbtiles"):
        from alphafence.plots.mbtiles import tiles_around

        held, attribution = tiles_around(tiles, bounds)
        return {"data": held, "attribution": args.tiles_attribution or attribution or ""}
    return {"url": tiles, "attribution": args.tiles_attribution}


def write_map_page(args, title, layers, note=None, bounds=None, legend_note=None) -> str:
    """Write ``--map``'s page with ``layers`` (and ``--tiles``' basemap); returns its path."""
    from alphafence.plots.webmap import bounds_of, write_map

    if bounds is None and getattr(args, "tiles", "") and args.tiles.lower().endswith(".mbtiles"):
        coords = [c for lay in layers for f in lay.get("features", ()) for c in _coords(f)]
        bounds = bounds_of(coords) if coords else None
    tiles = map_tiles(args, bounds) if bounds is not None or not _is_mbtiles(args) else None
    write_map(args.map, title, layers, note=note, tiles=tiles, bounds=bounds,
              legend_note=legend_note)  # fmt: skip
    return args.map


def onboard_map(args, records, result, title) -> str:
    """Write ``--map`` for a compile: the full-resolution fences it kept, the corridor and
    path, and the fence items as the vehicle will hold them (decoded from the items)."""
    from alphafence.mavlink.items import RETURN_POINT
    from alphafence.onboard.decode import decode_fence
    from alphafence.plots.webmap import fence_layers, onboard_layers
    from alphafence.plots.webmap_layers import corridor_layers

    dropped = set(result.dropped)
    kept = [r for r in records if r.site_id not in dropped]
    names = {"keep_out": "keep-out fences (full resolution)"}
    ret = next(((i.lon, i.lat) for i in result.items if i.command == RETURN_POINT), None)
    layers = [
        *corridor_layers(result.corridor, result.frame),
        *fence_layers(kept, names=names),
        *onboard_layers(decode_fence(result.items), ret, exclusion="#1565c0"),
    ]
    return write_map_page(args, title, layers)


def _is_mbtiles(args) -> bool:
    return bool(getattr(args, "tiles", None)) and args.tiles.lower().endswith(".mbtiles")


def _coords(f):
    def walk(c):
        if c and isinstance(c[0], (int, float)):
            yield c[:2]
        else:
            for x in c:
                yield from walk(x)

    g = f["geometry"]
    yield from walk(g.get("coordinates", []))
