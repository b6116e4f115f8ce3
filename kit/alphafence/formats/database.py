"""Read a geofence database: OSM (.osm.pbf, .osm), GeoJSON, ED-269 JSON, KML/KMZ, OpenAir."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from alphafence.errors import InputError, need
from alphafence.formats import kml, openair
from alphafence.formats.ed269 import looks_like_ed269, read_ed269_doc
from alphafence.formats.features import Database, select_bbox
from alphafence.formats.geojson import read_geojson_doc
from alphafence.formats.geojson_stream import (
    SEQ_SUFFIXES,
    is_sequence,
    iter_geojson,
    should_stream,
)
from alphafence.formats.jsonfile import read_json

OSM_SUFFIXES = (".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz", ".o5m", ".opl")


def osm_wants(paths):
    """What reading ``paths`` needs beyond the base install: pyosmium (4.0 or later, for
    ``osmium.filter``) for each OSM file, as :func:`alphafence.errors.need` takes it.

    Examples
    --------
    >>> osm_wants(["malta.osm.pbf", "zones.geojson"])
    [('osmium.filter', 'reading malta.osm.pbf')]
    """
    return [
        ("osmium.filter", f"reading {p}") for p in paths if str(p).lower().endswith(OSM_SUFFIXES)
    ]


def read_file(path, rules, repaired, skipped):
    """The restricted features of one file, read by its suffix: OSM through pyosmium, JSON
    as ED-269 when it looks like it, else as GeoJSON; KML/KMZ; OpenAir (``.openair``, or a
    ``.txt`` that starts with an ``AC`` record).

    Parameters
    ----------
    path : str or Path
    rules : Rules
    repaired : list
        Sources of invalid polygons are appended.
    skipped : collections.Counter
        Reasons for features left out are counted.

    Returns
    -------
    list of Feature
        When empty, ``skipped`` says so, naming the file (one of several databases that adds
        nothing is not dropped in silence).

    Raises
    ------
    InputError
        An unknown suffix, or what the reader raised.
    """
    name, left_out = str(path).lower(), sum(skipped.values())
    if name.endswith(OSM_SUFFIXES):
        need(*osm_wants([path]))
        from alphafence.formats.osm import read_osm  # pyosmium, only when OSM is read

        features = read_osm(path, rules, repaired, skipped)
    elif name.endswith(kml.SUFFIXES):
        features = kml.read_kml(path, rules, repaired, skipped)
    elif name.endswith(openair.SUFFIXES) or name.endswith(".txt") and openair.sniff(path):
        features = openair.read_openair(path, rules, repaired, skipped)
    elif should_stream(path):
        features = [f for batch in iter_geojson(path, rules, repaired, skipped) for f in batch]
    elif name.endswith((".geojson", ".json")):
        doc = read_json(path)
        if looks_like_ed269(doc):
            features = read_ed269_doc(path, doc, rules, repaired, skipped)
        else:
            features = read_geojson_doc(path, doc, rules, repaired, skipped)
    else:
        raise InputError(
            path,
            "unknown database format (expected .osm.pbf, .osm, .geojson, .geojsonl, ED-269 .json, "
            ".kml, .kmz or OpenAir .openair/.txt)",
        )
    if not features:
        skipped[f"all of {path}: it holds no restricted features (rules: {rules.source})"] += (
            sum(skipped.values()) - left_out
        )
    return features


def read_database(paths, rules, bbox=None, *, bbox_name="the bounding box") -> Database:
    """Read every restricted feature (by ``rules``) from the given files.

    Raises InputError with a one-line message on bad input or an empty selection
    (``bbox_name`` says what the box is in that message: the command line passes ``--bbox``).

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.formats.rules import load_rules
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> db = read_database(str(scene), load_rules())
    >>> len(db.features), db.repaired
    (16, ['way/1015'])
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    repaired, skipped, features = [], Counter(), []
    for path in paths:
        features.extend(read_file(path, rules, repaired, skipped))
    selected = select_bbox(features, bbox)
    if not selected:
        where = ", ".join(str(p) for p in paths)
        why = f" inside {bbox_name} {','.join(f'{v:g}' for v in bbox)}" if bbox else ""
        raise InputError(where, f"no restricted features{why} (rules: {rules.source})")
    return Database(selected, [str(p) for p in paths], repaired, skipped, bbox)


class DatabaseStream:
    """A geofence database read in batches of restricted features, for builds too large to
    hold every feature at once: large GeoJSON is streamed; OSM, ED-269 and small GeoJSON files
    come as one batch each.

    Attributes
    ----------
    files : list of str
    repaired : list of str
    skipped : collections.Counter
    bbox : tuple, optional
    count : int
        Restricted features yielded so far.

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.formats.rules import load_rules
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> stream = DatabaseStream([str(scene)], load_rules())
    >>> [len(batch) for batch in stream.batches()], stream.count
    ([16], 16)
    """

    def __init__(self, paths, rules, bbox=None, *, bbox_name="the bounding box"):
        if isinstance(paths, (str, Path)):
            paths = [paths]
        self.paths = list(paths)
        self.files = [str(p) for p in self.paths]
        self.rules = rules
        self.bbox = bbox
        self.bbox_name = bbox_name
        self.repaired, self.skipped, self.count = [], Counter(), 0

    def batches(self, sequences=None):
        """Lists of restricted features (inside the bbox), file by file.

        Parameters
        ----------
        sequences : callable, optional
            ``sequences(path, rules, bbox, repaired, skipped)`` -> the parts of a GeoJSON
            text sequence, each inside ``bbox`` and of some length (lists of Feature or
            another reader's parts, yielded as they come), ``repaired`` and ``skipped``
            extended as they are read; or None to read the file here
            (:func:`alphafence.build.read_jobs.sequence_reader` reads in worker processes).

        Raises
        ------
        InputError
            As :func:`read_database`, including when no file holds a restricted feature.
        """
        for path in self.paths:
            parts = None
            if sequences is not None and is_sequence(path):
                parts = sequences(path, self.rules, self.bbox, self.repaired, self.skipped)
            inside = parts is not None
            if parts is None:
                parts = self._parts(path)
            before = self.count
            for part in parts:
                part = part if inside else select_bbox(part, self.bbox)
                if len(part):
                    self.count += len(part)
                    yield part
            if self.count == before and parts is not None and not isinstance(parts, list):
                note = (
                    f"all of {path}: it holds no restricted features (rules: {self.rules.source})"
                )
                self.skipped[note] += 0  # said, as read_file says it for files read whole
        if not self.count:
            where = ", ".join(self.files)
            why = ""
            if self.bbox:
                why = f" inside {self.bbox_name} {','.join(f'{v:g}' for v in self.bbox)}"
            raise InputError(where, f"no restricted features{why} (rules: {self.rules.source})")

    def _parts(self, path):
        """The file's features, as they come: batch by batch, or in one list."""
        if should_stream(path) and str(path).lower().endswith((".json", ".geojson", *SEQ_SUFFIXES)):
            return iter_geojson(path, self.rules, self.repaired, self.skipped)
        if str(path).lower().endswith(OSM_SUFFIXES):
            need(*osm_wants([path]))
            from alphafence.formats.osm import iter_osm  # pyosmium, only when OSM is read

            return iter_osm(path, self.rules, self.repaired, self.skipped)
        return [read_file(path, self.rules, self.repaired, self.skipped)]

    def database(self, features=()) -> Database:
        """What was read, as a :class:`Database` (holding ``features``)."""
        return Database(list(features), self.files, self.repaired, self.skipped, self.bbox)
