"""MBTiles files (an SQLite database of map tiles, MBTiles 1.3) read for a map page: the tiles
around the data at a few zoom levels, as data URIs the page holds, within a size cap."""

from __future__ import annotations

import base64
import math
import sqlite3
from pathlib import Path

from alphafence.errors import InputError

#: Most bytes of tiles a page holds (before base64).
MAX_BYTES = 20 * 1024 * 1024
#: Most tiles a zoom level may need to cover the data; deeper levels are left out.
MAX_TILES_PER_ZOOM = 256
MIME = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "webp": "image/webp"}


def _connect(path):
    if not Path(path).is_file():
        raise InputError(path, "no such MBTiles file")
    try:
        db = sqlite3.connect(f"{Path(path).resolve().as_uri()}?mode=ro", uri=True)
        db.execute("SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles LIMIT 1")
        return db
    except sqlite3.DatabaseError as exc:
        raise InputError(path, f"not an MBTiles file (SQLite with a tiles table): {exc}") from None


def check_mbtiles(path) -> None:
    """Refuse a file that is not an MBTiles database of raster tiles, in one line.

    Raises
    ------
    InputError
    """
    db = _connect(path)
    try:
        fmt = _metadata(db).get("format", "png").lower()
    finally:
        db.close()
    if fmt not in MIME:
        raise InputError(path, f"holds {fmt} tiles; a map page shows png, jpg or webp tiles")


def _metadata(db) -> dict:
    try:
        return dict(db.execute("SELECT name, value FROM metadata").fetchall())
    except sqlite3.DatabaseError:
        return {}


def tile_range(bounds, zoom):
    """The XYZ tile columns and rows covering ``bounds`` (``[[south, west], [north, east]]``)
    at ``zoom``: ``(x0, x1, y0, y1)``, inclusive.

    Examples
    --------
    >>> tile_range([[35.8, 14.3], [36.1, 14.6]], 10)
    (552, 553, 401, 402)
    """
    (s, w), (n, e) = bounds
    count = 2**zoom

    def col(lon):
        return min(count - 1, max(0, int((lon + 180.0) / 360.0 * count)))

    def row(lat):
        lat = max(-85.0511, min(85.0511, lat))
        y = (1 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2
        return min(count - 1, max(0, int(y * count)))

    return col(w), col(e), row(n), row(s)


def tiles_around(path, bounds, max_bytes=MAX_BYTES):
    """The tiles of ``path`` covering ``bounds`` at every zoom level where that takes at most
    :data:`MAX_TILES_PER_ZOOM` tiles, as ``{"z/x/y": data URI}``, and the file's attribution.

    Raises
    ------
    InputError
        The tiles would take more than ``max_bytes``.
    """
    db = _connect(path)
    try:
        meta = _metadata(db)
        mime = MIME.get(meta.get("format", "png").lower(), "image/png")
        zooms = [z for (z,) in db.execute("SELECT DISTINCT zoom_level FROM tiles ORDER BY 1")]
        out, size = {}, 0
        for z in zooms:
            x0, x1, y0, y1 = tile_range(bounds, z)
            if (x1 - x0 + 1) * (y1 - y0 + 1) > MAX_TILES_PER_ZOOM:
                continue
            flip = 2**z - 1  # MBTiles rows count from the south (TMS)
            rows = db.execute(
                "SELECT tile_column, tile_row, tile_data FROM tiles WHERE zoom_level = ? "
                "AND tile_column BETWEEN ? AND ? AND tile_row BETWEEN ? AND ?",
                (z, x0, x1, flip - y1, flip - y0),
            )
            for x, tms_row, blob in rows:
                size += len(blob)
                if size > max_bytes:
                    raise InputError(
                        path,
                        f"the tiles around the data take more than {max_bytes / 2**20:.0f} MB "
                        f"(at zoom {z}); give a file with fewer zoom levels, or a tile URL",
                    )
                uri = f"data:{mime};base64,{base64.b64encode(blob).decode('ascii')}"
                out[f"{z}/{x}/{flip - tms_row}"] = uri
        return out, meta.get("attribution")
    finally:
        db.close()
