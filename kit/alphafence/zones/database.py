"""Read a geofence database: OSM (.osm.pbf, .osm), GeoJSON, ED-269 JSON, KML/KMZ, OpenAir."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from alphafence.errors import InputError, InputErrors, need
from alphafence.zones import kml, openair
from alphafence.zones.ed269 import looks_like_ed269, read_ed269_doc
from alphafence.zones.features import Database, select_bbox
from alphafence.zones.geojson import read_geojson_doc
from alphafence.zones.geojson_stream import (
    SEQ_SUFFIXES,
    is_sequence,
    iter_geojson,
    should_stream,
)
from alphafence.zones.jsonfile import read_json
from alphafence.zones.mistakes import box_swap_hint, swapped_box

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


def is_openair(path) -> bool:
    """Whether ``path`` is read as OpenAir: ``.openair``, or a ``.txt`` that starts with an
    ``AC`` record."""
    name = str(path).lower()
    return name.endswith(openair.SUFFIXES) or name.endswith(".txt") and openair.sniff(path)


def read_file(path, rules, repaired, skipped, notes=None, invalid=None):
    """The restricted features of one file, read by its suffix: OSM through pyosmium, JSON
    as ED-269 when it looks like it, else as GeoJSON; KML/KMZ; OpenAir (:func:`is_openair`).

    Parameters
    ----------
    path : str or Path
    rules : Rules
    repaired : list
        Sources of invalid polygons are appended.
    skipped : collections.Counter
        Reasons for features left out are counted.
    notes : list, optional
        What was read other than as written is said here, a line each (OpenAir limits
        without a numeric meaning, widened).
    invalid : list, optional
        When given, OpenAir airspaces that cannot be read as areas are left out and described
        here; when None, they are raised, every one of the file at once.

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
        from alphafence.zones.osm import read_osm  # pyosmium, only when OSM is read

        features = read_osm(path, rules, repaired, skipped)
    elif name.endswith(kml.SUFFIXES):
        features = kml.read_kml(path, rules, repaired, skipped, invalid)
    elif is_openair(path):
        features = openair.read_openair(path, rules, repaired, skipped, notes, invalid)
    elif should_stream(path):
        batches = iter_geojson(path, rules, repaired, skipped, invalid=invalid)
        features = [f for batch in batches for f in batch]
    elif name.endswith((".geojson", ".json")):
        doc = read_json(path)
        if looks_like_ed269(doc):
            features = read_ed269_doc(path, doc, rules, repaired, skipped, invalid)
        else:
            features = read_geojson_doc(path, doc, rules, repaired, skipped, invalid)
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


def read_openair_files(paths, rules, repaired, skipped, notes, invalid=None) -> dict:
    """The restricted features of the OpenAir files among ``paths``, read before the rest
    so that every fault of every one of them is known at once.

    Parameters
    ----------
    paths : list
    rules, repaired, skipped, notes, invalid
        As :func:`read_file` takes them.

    Returns
    -------
    dict
        Index in ``paths`` -> its features.

    Raises
    ------
    InputError
        :class:`~alphafence.errors.InputErrors` when there are several faults, listing them
        all, a line each.
    """
    read, faults = {}, []
    for i, path in enumerate(paths):
        if is_openair(path):
            try:
                read[i] = read_file(path, rules, repaired, skipped, notes, invalid)
            except InputErrors as exc:
                faults.extend(exc.errors)
            except InputError as exc:
                faults.append(exc)
    if len(faults) == 1:
        raise faults[0]
    if faults:
        raise InputErrors(", ".join(sorted({f.path for f in faults})), faults)
    return read


def read_database(
    paths, rules, bbox=None, *, bbox_name="the bounding box", skip_invalid=False
) -> Database:
    """Read every restricted feature (by ``rules``) from the given files.

    Raises InputError with a one-line message on bad input or an empty selection
    (``bbox_name`` says what the box is in that message: the command line passes ``--bbox``);
    every fault of the OpenAir files at once (:class:`~alphafence.errors.InputErrors`), unless
    ``skip_invalid``: then the airspaces that cannot be read as areas are left out and listed
    in the database's ``invalid``.

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.zones.rules import load_rules
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> db = read_database(str(scene), load_rules())
    >>> len(db.features), db.repaired
    (16, ['way/1015'])
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    repaired, skipped, features, notes = [], Counter(), [], []
    invalid = [] if skip_invalid else None
    ahead = read_openair_files(paths, rules, repaired, skipped, notes, invalid)
    for i, path in enumerate(paths):
        features.extend(
            ahead[i] if i in ahead else read_file(path, rules, repaired, skipped, notes, invalid)
        )
    selected = select_bbox(features, bbox)
    if not selected:
        swapped = swapped_box(bbox) if bbox else None
        hits = len(select_bbox(features, swapped)) if swapped else 0
        raise _nothing_inside(paths, bbox, bbox_name, rules, hits)
    files = [str(p) for p in paths]
    return Database(selected, files, repaired, skipped, bbox, notes, invalid or [])


def _nothing_inside(paths, bbox, bbox_name, rules, swap_hits):
    """The error of a selection that holds nothing: the box, and the box meant when its swap
    selects ``swap_hits`` features."""
    where = ", ".join(str(p) for p in paths)
    why = f" inside {bbox_name} {','.join(f'{v:g}' for v in bbox)}" if bbox else ""
    hint = "; " + box_swap_hint(bbox_name, bbox, swap_hits, "features") if swap_hits else ""
    return InputError(where, f"no restricted features{why} (rules: {rules.source}){hint}")


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
    notes : list of str
        What was read other than as written (see :func:`read_file`).
    invalid : list of dict
        With ``skip_invalid``: the OpenAir airspaces left out as no area, and why.

    Examples
    --------
    >>> from importlib import resources
    >>> from alphafence.zones.rules import load_rules
    >>> scene = resources.files("alphafence").joinpath("data/demo-scene.geojson")
    >>> stream = DatabaseStream([str(scene)], load_rules())
    >>> [len(batch) for batch in stream.batches()], stream.count
    ([16], 16)
    """

    def __init__(
        self, paths, rules, bbox=None, *, bbox_name="the bounding box", skip_invalid=False
    ):
        if isinstance(paths, (str, Path)):
            paths = [paths]
        self.paths = list(paths)
        self.files = [str(p) for p in self.paths]
        self.rules = rules
        self.bbox = bbox
        self.bbox_name = bbox_name
        self.repaired, self.skipped, self.count = [], Counter(), 0
        self.skip_invalid = skip_invalid
        self.notes, self.invalid, self._ahead = [], [], None
        self._swap = 0  # features inside the box read the other way round (lat,lon)

    def read_ahead(self) -> None:
        """Read the OpenAir files now, before the others (:meth:`batches` does it first): a
        build stops on their faults before it reads or writes anything else, and knows the
        airspaces it leaves out (``skip_invalid``) before its outputs are opened.

        Raises
        ------
        InputError
            Every fault of the OpenAir files at once (unless ``skip_invalid``).
        """
        if self._ahead is None:
            invalid = self.invalid if self.skip_invalid else None
            self._ahead = read_openair_files(
                self.paths, self.rules, self.repaired, self.skipped, self.notes, invalid
            )

    def batches(self, sequences=None):
        """Lists of restricted features (inside the bbox), file by file.

        Parameters
        ----------
        sequences : callable, optional
            ``sequences(path, rules, bbox, repaired, skipped, invalid)`` -> the parts of a
            GeoJSON text sequence, each inside ``bbox`` and of some length (lists of Feature
            or another reader's parts, yielded as they come), ``repaired`` and ``skipped``
            extended as they are read, malformed features described in ``invalid`` (or, None,
            raised at the file's end); or None to read the file here
            (:func:`alphafence.fencing.read_jobs.sequence_reader` reads in worker processes).

        Raises
        ------
        InputError
            As :func:`read_database`, including when no file holds a restricted feature.
        """
        self.read_ahead()
        swapped = swapped_box(self.bbox) if self.bbox else None
        for i, path in enumerate(self.paths):
            parts, inside = None, False
            if i in self._ahead:
                parts = [self._ahead.pop(i)]  # read whole, selected by the bbox below
            elif sequences is not None and is_sequence(path):
                invalid = self.invalid if self.skip_invalid else None
                parts = sequences(path, self.rules, self.bbox, self.repaired, self.skipped, invalid)
                inside = parts is not None
            if parts is None:
                parts = self._parts(path)
            before = self.count
            for part in parts:
                if not inside and swapped and not self.count:  # for a box typed lat,lon
                    self._swap += len(select_bbox(part, swapped))
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
            raise _nothing_inside(self.files, self.bbox, self.bbox_name, self.rules, self._swap)

    def _parts(self, path):
        """The file's features, as they come: batch by batch, or in one list."""
        if should_stream(path) and str(path).lower().endswith((".json", ".geojson", *SEQ_SUFFIXES)):
            invalid = self.invalid if self.skip_invalid else None
            return iter_geojson(path, self.rules, self.repaired, self.skipped, invalid=invalid)
        if str(path).lower().endswith(OSM_SUFFIXES):
            need(*osm_wants([path]))
            from alphafence.zones.osm import iter_osm  # pyosmium, only when OSM is read

            return iter_osm(path, self.rules, self.repaired, self.skipped)
        invalid = self.invalid if self.skip_invalid else None
        return [read_file(path, self.rules, self.repaired, self.skipped, self.notes, invalid)]

    def database(self, features=()) -> Database:
        """What was read, as a :class:`Database` (holding ``features``)."""
        return Database(
            list(features),
            self.files,
            self.repaired,
            self.skipped,
            self.bbox,
            self.notes,
            self.invalid,
        )
