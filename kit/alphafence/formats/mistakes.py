"""Map databases given where fences are expected: told by suffix and by first bytes, and
refused in one line that says how to build fences from them.

``alphafence build`` reads map databases (an OpenStreetMap extract, a geozone list) and
writes fences; every other verb reads fences. A database handed to one of them would
otherwise fail deep in a reader ("not UTF-8 text", "malformed JSON"); :func:`refuse_map_database`
says what the file is and what to run instead.
"""

from __future__ import annotations

import re

from alphafence.errors import InputError

# suffixes ``alphafence build`` reads as OpenStreetMap (formats.database.OSM_SUFFIXES)
OSM_SUFFIXES = (".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz", ".o5m", ".opl")
# databases build does not read: they are converted to GeoJSON first
OTHER_SUFFIXES = {
    ".gpkg": "a GeoPackage database",
    ".mbtiles": "an MBTiles database",
    ".sqlite": "an SQLite database",
    ".db": "a database file",
    ".shp": "a shapefile",
}
# PBF: a 4-byte big-endian BlobHeader length, then the BlobHeader whose field 1 (type) is the
# string "OSMHeader" (or "OSMData"): protobuf tag 0x0a, then its length
_PBF_TYPES = (b"\x0a\x09OSMHeader", b"\x0a\x07OSMData")
_OSM_XML = re.compile(rb"^\s*(?:<\?xml[^>]*\?>\s*)?(?:<!--.*?-->\s*)*<osm[\s>]", re.S)
_MAGIC = (
    (b"SQLite format 3\x00", "an SQLite database (GeoPackage, MBTiles, SpatiaLite)"),
    (b"\x00\x00\x27\x0a", "a shapefile"),
)


def map_database_kind(path, head=None):
    """What map database ``path`` is, by its suffix or its first bytes, and the suffix
    ``alphafence build`` reads it under.

    Parameters
    ----------
    path : str or Path
    head : bytes, optional
        The file's first bytes (read here when not given; an unreadable file is no database,
        for its reader to report).

    Returns
    -------
    tuple or None
        ``(what, suffix)``: what it is (``"an OpenStreetMap extract"``) and the suffix build
        reads it under (its own, ``".osm.pbf"`` for a PBF of another name, or None for a
        database build does not read); None for anything else (fence files, KML and KMZ
        included).

    Examples
    --------
    >>> map_database_kind("monaco.osm.pbf", b"")
    ('an OpenStreetMap extract', '.osm.pbf')
    >>> map_database_kind("x.bin", b"\\x00\\x00\\x00\\x0d\\x0a\\x09OSMHeader\\x18")
    ('an OpenStreetMap PBF extract', '.osm.pbf')
    >>> map_database_kind("fences.geojson", b'{"type": "FeatureCollection"}') is None
    True
    """
    name = str(path).lower()
    for suffix in OSM_SUFFIXES:
        if name.endswith(suffix):
            return "an OpenStreetMap extract", suffix
    for suffix, what in OTHER_SUFFIXES.items():
        if name.endswith(suffix):
            return what, None
    if head is None:
        try:
            with open(path, "rb") as fh:
                head = fh.read(4096)
        except OSError:
            return None
    if head[4:15] == _PBF_TYPES[0] or head[4:13] == _PBF_TYPES[1]:
        return "an OpenStreetMap PBF extract", ".osm.pbf"
    if _OSM_XML.match(head[:4096]):
        return "an OpenStreetMap XML extract", ".osm"
    for magic, what in _MAGIC:
        if head.startswith(magic):
            return what, None
    return None


def database_message(path, what="a map database", suffix=".geojson"):
    """The one-line refusal of the map database ``path`` where fences are expected: what it
    is, and how to make fences of it.

    Parameters
    ----------
    path : str or Path
    what : str
        What it is (``"an OpenStreetMap extract"``).
    suffix : str or None
        The suffix ``alphafence build`` reads it under: its own (the command names it as
        it is), another (the command names it renamed) or None (a database build does not
        read: export it to a format build reads first).

    Examples
    --------
    >>> database_message("monaco.osm.pbf", "an OpenStreetMap extract", ".osm.pbf")
    'a map database (an OpenStreetMap extract), not fences: build fences first: alphafence build monaco.osm.pbf -o fences.geojson'
    """
    path = str(path)
    head = f"a map database ({what}), not fences: build fences first: "
    if suffix is None:
        return (
            f"a map database ({what}), not fences, and not one alphafence build reads: export "
            "its zones as GeoJSON, ED-269, KML or OpenAir, then build fences of that: "
            "alphafence build ZONES -o fences.geojson"
        )
    if not path.lower().endswith(suffix):
        # build tells OSM files by their suffix
        renamed = (
            path.rsplit(".", 1)[0] + suffix if "." in path.rsplit("/", 1)[-1] else path + suffix
        )
        return f"{head}renamed {suffix}: alphafence build {renamed} -o fences.geojson"
    return head + f"alphafence build {path} -o fences.geojson"


def refuse_map_database(path, head=None) -> None:
    """Raise an :class:`~alphafence.errors.InputError` when ``path`` is a map database
    (:func:`map_database_kind`), saying how to build fences of it; else do nothing.

    Raises
    ------
    InputError
        ``malta.osm.pbf: a map database (an OpenStreetMap extract), not fences: build fences
        first: alphafence build malta.osm.pbf -o fences.geojson``.
    """
    found = map_database_kind(path, head)
    if found is not None:
        raise InputError(path, database_message(path, *found))
