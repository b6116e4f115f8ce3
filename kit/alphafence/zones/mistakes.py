"""Easy mistakes in what is given, caught and said in one line with what was meant.

* A map database given where fences are expected, told by suffix and by first bytes.
  ``alphafence build`` reads map databases (an OpenStreetMap extract, a geozone list) and
  writes fences; every other verb reads fences. A database handed to one of them would
  otherwise fail deep in a reader ("not UTF-8 text", "malformed JSON");
  :func:`refuse_map_database` says what the file is and what to run instead.
* Coordinates typed the wrong way round: boxes are ``MINLON,MINLAT,MAXLON,MAXLAT`` (GIS
  order) and positions ``LAT,LON`` (MAVLink's order). A box that selects no fence while its
  swap selects some (:func:`check_box`), or a position far from every fence whose swap lies
  among them (:func:`check_point`), is refused with the swapped value to give instead.
* An output named with a suffix of another format: refused by :func:`output_format`, which
  tells the format by the suffix.
"""

from __future__ import annotations

import re

import numpy as np
import shapely

from alphafence.errors import InputError
from alphafence.geo.coords import valid_lonlat
from alphafence.geo.frame import LocalFrame

# suffixes ``alphafence build`` reads as OpenStreetMap (zones.database.OSM_SUFFIXES)
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


# -- coordinates in the wrong order ------------------------------------------------------------
# a position this far from every fence, whose swap lies among them, was typed the wrong way round
FAR_M = 50_000.0
NEAR_M = 10_000.0  # "among them": inside their extent, or this close to one


def _deg(value) -> str:
    """A coordinate as typed: up to 7 decimals (MAVLink's resolution), no trailing zeros."""
    return f"{float(value):.7f}".rstrip("0").rstrip(".")


def _distances_m(where, geoms):
    """Metres from ``where`` (a WGS84 geometry) to each of ``geoms``, in a frame centred on
    it (an azimuthal equidistant one: exact from its centre); what does not project (the
    antipode) is infinitely far."""
    frame = LocalFrame.around(where)
    d = shapely.distance(frame.geom_to_local(where), frame.geom_to_local(geoms))
    return np.nan_to_num(np.asarray(d, float), nan=np.inf, posinf=np.inf)


def point_swap(lonlat, geoms):
    """How far the position ``lonlat`` is from the nearest of ``geoms``, and its swap when it
    looks typed the wrong way round: more than :data:`FAR_M` from every geometry while its
    swap (lat read as lon) lies inside their extent or within :data:`NEAR_M` of one.

    Parameters
    ----------
    lonlat : tuple of float
        ``(lon, lat)`` as read.
    geoms : sequence of shapely geometries
        WGS84 (lon, lat), e.g. the fences' geometries.

    Returns
    -------
    distance_m : float
        Metres to the nearest geometry (``inf`` when there is none).
    swapped : tuple or None
        ``(lon, lat)`` of the swapped position when it is the likelier one, else None.

    Examples
    --------
    >>> import shapely
    >>> monaco = [shapely.box(7.41, 43.72, 7.44, 43.75)]
    >>> d, swapped = point_swap((43.74, 7.43), monaco)  # "--to 7.43,43.74": lon,lat typed
    >>> round(d / 1000), swapped
    (5349, (7.43, 43.74))
    >>> point_swap((7.5, 43.7), monaco)[1] is None  # 6 km away: taken as typed
    True
    """
    geoms = np.asarray(list(geoms), dtype=object)
    if not len(geoms):
        return float("inf"), None
    lon, lat = float(lonlat[0]), float(lonlat[1])
    distance = float(_distances_m(shapely.Point(lon, lat), geoms).min())
    if distance <= FAR_M or not valid_lonlat(lat, lon):
        return distance, None
    swap = shapely.Point(lat, lon)
    extent = shapely.box(*shapely.total_bounds(geoms))
    if extent.covers(swap) or float(_distances_m(swap, geoms).min()) <= NEAR_M:
        return distance, (lat, lon)
    return distance, None


def check_point(name, lonlat, geoms, source) -> float:
    """Refuse the position ``lonlat`` (``(lon, lat)``, typed ``LAT,LON``) when it looks typed
    the wrong way round (:func:`point_swap`), suggesting the swap.

    Parameters
    ----------
    name : str
        What the position is, named in the message (the option: ``"--to"``).
    lonlat : tuple of float
    geoms : sequence of shapely geometries
        The fences' geometries (WGS84).
    source : str
        Where they come from (the fence file), for the message.

    Returns
    -------
    float
        Metres from the position to the nearest geometry.

    Raises
    ------
    InputError
        ``--to: 7.43,43.74 (LAT,LON) is 5,349 km from every fence of f.geojson; swapped,
        43.74,7.43 lies among them: did you mean --to 43.74,7.43?``
    """
    distance, swapped = point_swap(lonlat, geoms)
    if swapped is not None:
        typed = f"{_deg(lonlat[1])},{_deg(lonlat[0])}"
        meant = f"{_deg(swapped[1])},{_deg(swapped[0])}"
        raise InputError(
            name,
            f"{typed} (LAT,LON) is {distance / 1000:,.0f} km from every fence of {source}; "
            f"swapped, {meant} lies among them: did you mean {name} {meant}?",
        )
    return distance


def swapped_box(bbox):
    """The box ``(minlon, minlat, maxlon, maxlat)`` read the other way round, as if typed
    ``MINLAT,MINLON,MAXLAT,MAXLON``, or None when that is no box on Earth.

    Examples
    --------
    >>> swapped_box((43.72, 7.41, 43.75, 7.44))
    (7.41, 43.72, 7.44, 43.75)
    >>> swapped_box((100.0, 10.0, 101.0, 11.0)) is None  # 100 is no latitude
    True
    """
    swapped = (bbox[1], bbox[0], bbox[3], bbox[2])
    ok = valid_lonlat(swapped[0], swapped[1]) and valid_lonlat(swapped[2], swapped[3])
    return swapped if ok else None


def box_count(bbox, geoms, reach_m=0.0) -> int:
    """How many of ``geoms`` (WGS84) lie within ``reach_m`` metres of the box ``bbox``
    (``(minlon, minlat, maxlon, maxlat)``; 0: that meet it)."""
    geoms = np.asarray(list(geoms), dtype=object)
    if not len(geoms):
        return 0
    box = shapely.box(*bbox)
    if reach_m <= 0:
        return int(shapely.intersects(geoms, box).sum())
    return int((_distances_m(box, geoms) <= reach_m).sum())


def box_swap_hint(name, bbox, count, what="fences"):
    """The end of a message about the box ``bbox`` that selects nothing while its swap
    selects ``count`` of ``what``: the box to give instead.

    Examples
    --------
    >>> box_swap_hint("--bbox", (43.72, 7.41, 43.75, 7.44), 3)
    '--bbox is MINLON,MINLAT,MAXLON,MAXLAT; swapped to lon,lat it selects 3 fences: did you mean --bbox 7.41,43.72,7.44,43.75?'
    """
    meant = ",".join(_deg(v) for v in swapped_box(bbox))
    return (
        f"{name} is MINLON,MINLAT,MAXLON,MAXLAT; swapped to lon,lat it selects {count:,} "
        f"{what}: did you mean {name} {meant}?"
    )


def check_box(name, bbox, geoms, source, reach_m=0.0) -> None:
    """Refuse the box ``bbox`` when no geometry lies within ``reach_m`` of it while its swap
    (:func:`swapped_box`) selects some, suggesting the swap; else do nothing.

    Parameters
    ----------
    name : str
        What the box is, named in the message (the option: ``"--bbox"``).
    bbox : tuple
        ``(minlon, minlat, maxlon, maxlat)`` as read.
    geoms : sequence of shapely geometries
        The fences' geometries (WGS84).
    source : str
        Where they come from (the fence file), for the message.
    reach_m : float
        A geometry this close to the box is selected.

    Raises
    ------
    InputError
        ``--bbox: no fence of f.geojson within 2000 m of 43.72,7.41,43.75,7.44; --bbox is
        MINLON,MINLAT,MAXLON,MAXLAT; swapped to lon,lat it selects 8 fences: did you mean
        --bbox 7.41,43.72,7.44,43.75?``
    """
    swapped = swapped_box(bbox)
    if swapped is None or box_count(bbox, geoms, reach_m):
        return
    count = box_count(swapped, geoms, reach_m)
    if count:
        near = f"within {reach_m:g} m of" if reach_m > 0 else "in"
        typed = ",".join(_deg(v) for v in bbox)
        raise InputError(
            name, f"no fence of {source} {near} {typed}; " + box_swap_hint(name, bbox, count)
        )


# -- an output's format, by its suffix ---------------------------------------------------------
PLAN_OUTPUTS = {".plan": "plan", ".waypoints": "waypoints"}


def output_format(path, formats=PLAN_OUTPUTS, what="output") -> str:
    """The format an output is written in, by its suffix (case ignored), or a refusal naming
    the suffixes that are written: a file is never written in a format its name belies.

    Parameters
    ----------
    path : str or Path
    formats : dict
        Suffix -> format (default: ``.plan`` a QGroundControl plan, ``.waypoints`` a QGC WPL
        file).
    what : str
        What the output is, for the message (``"mission output"``).

    Raises
    ------
    InputError
        ``r.geojson: unknown mission output format '.geojson' (use .plan or .waypoints)``.

    Examples
    --------
    >>> output_format("mission.WAYPOINTS")
    'waypoints'
    >>> output_format("r.geojson", what="mission output")
    Traceback (most recent call last):
    ...
    alphafence.errors.InputError: r.geojson: unknown mission output format '.geojson' (use .plan or .waypoints)
    """
    name = str(path).rsplit("/", 1)[-1].lower()
    suffix = "." + name.rsplit(".", 1)[-1] if "." in name else ""
    if suffix in formats:
        return formats[suffix]
    known = list(formats)
    said = f"{', '.join(known[:-1])} or {known[-1]}" if len(known) > 1 else known[0]
    raise InputError(path, f"unknown {what} format {suffix or '(none)'!r} (use {said})")
