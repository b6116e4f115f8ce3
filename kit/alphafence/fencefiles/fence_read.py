"""Fence files of any output format read back as ``fence_geojson.FenceRecord``: the kit's fence
GeoJSON, GeoJSON text sequences (RS-separated or one Feature per line) and GeoParquet; and the
fence files other tools write, read as they are: a QGroundControl plan's geoFence, a fence
``.waypoints`` file and ArduPilot's legacy fence file (inclusion -> keep-in, exclusion ->
keep-out, circles kept as circles), KML/KMZ and OpenAir zones (keep-out, their bands kept).

A sequence is read one record at a time and a GeoParquet file one row group batch at a time,
so neither is ever held whole as text; each record is checked as ``fence_geojson`` checks a
feature of its FeatureCollection.
"""

from __future__ import annotations

import json

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence.errors import InputError
from alphafence.fencefiles import fence_geojson, fence_parquet
from alphafence.fencefiles.fence_geojson import _kind_of, fence_record
from alphafence.zones.features import check_coordinates
from alphafence.zones.jsonfile import max_json_bytes
from alphafence.zones.mistakes import refuse_map_database

SEQ_SUFFIXES = (".geojsonl", ".geojsons", ".geojsonseq")
GEOJSON_SUFFIXES = (".geojson", ".json")
PARQUET_SUFFIXES = (".parquet",)
OTHER_SUFFIXES = {
    ".plan": "plan",
    ".waypoints": "waypoints",
    ".kml": "kml",
    ".kmz": "kml",
    ".openair": "openair",
}
CHUNK = 1 << 20


def read_fence_file(path) -> list:
    """The fences of a fence file, whatever format ``alphafence build`` wrote it in.

    The format is told by the suffix (``.geojson``/``.json``, ``.geojsonl``/``.geojsons``/
    ``.geojsonseq``, ``.parquet``, ``.plan``, ``.waypoints``, ``.kml``/``.kmz``, ``.openair``);
    any other suffix (``.txt``) by the first bytes (RS: a sequence, ``PAR1``: Parquet, a zip or
    ``<kml``: KML, ``QGC WPL``: waypoints, a ``geoFence`` key: a plan, ``lat lon`` lines:
    ArduPilot's legacy fence, an ``AC`` record: OpenAir, else GeoJSON).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of FenceRecord
        As ``fence_geojson.read_fences`` returns them.

    Raises
    ------
    InputError
        One line naming the file and the feature (or record, or row) that is malformed, or
        saying that the file is a map database to build fences of (an OSM extract).
    MissingDependency
        A ``.parquet`` file without pyarrow installed, or a KML file without lxml.
    """
    refuse_map_database(path)  # an OSM extract where fences belong: say to build them
    kind = _kind(path)
    if kind == "seq":
        return read_sequence(path)
    if kind == "parquet":
        return read_geoparquet(path)
    if kind == "geojson":
        return fence_geojson.read_fences(path)
    return _other(path, kind)


def _other(path, kind):
    """The fences of a fence file another tool wrote."""
    from alphafence.fencefiles import ardupilot_fence, qgc_plan, qgc_wpl, volume_fences

    if kind == "plan":
        return ardupilot_fence.item_fences(path, qgc_plan.read_plan_fence(path), "plan")
    if kind == "waypoints":
        return ardupilot_fence.item_fences(path, qgc_wpl.read_waypoints_fence(path), "waypoints")
    if kind == "kml":
        return volume_fences.read_kml_fences(path)
    if kind == "openair":
        return volume_fences.read_openair_fences(path)
    return ardupilot_fence.read_legacy_fence(path)


def _kind(path):
    suffix = str(path).lower().rsplit("/", 1)[-1]
    suffix = "." + suffix.rsplit(".", 1)[-1] if "." in suffix else ""
    if suffix in SEQ_SUFFIXES:
        return "seq"
    if suffix in PARQUET_SUFFIXES:
        return "parquet"
    if suffix in GEOJSON_SUFFIXES:
        return "geojson"
    if suffix in OTHER_SUFFIXES:
        return OTHER_SUFFIXES[suffix]
    try:
        with open(path, "rb") as fh:
            head = fh.read(CHUNK)
    except OSError:
        return "geojson"  # its reader says what is wrong with the path
    return _sniff(head)


def _sniff(head):
    """The format of a file by its first bytes."""
    from alphafence.fencefiles.ardupilot_fence import looks_like_legacy_fence
    from alphafence.zones.kml import looks_like_kml
    from alphafence.zones.openair import looks_like_openair

    if head[:1] == b"\x1e":
        return "seq"
    if head[:4] == b"PAR1":
        return "parquet"
    if looks_like_kml(head):
        return "kml"
    text = head.decode("latin-1")
    if text.lstrip().startswith("QGC WPL"):
        return "waypoints"
    if text.lstrip().startswith("{"):
        return "plan" if '"geoFence"' in text else "geojson"
    if looks_like_legacy_fence(text):
        return "legacy"
    return "openair" if looks_like_openair(text) else "geojson"


def _checked(path, out, what):
    if out:
        geoms = np.array([f.geometry for f in out], dtype=object)
        check_coordinates(path, geoms, lambda k: f"{what} {k} ({out[k].site_id})")
    return out


def read_sequence(path) -> list:
    """The fences of a GeoJSON text sequence: RS-separated records (RFC 8142) or one
    Feature per line, read a record at a time (FeatureCollection records are taken
    feature by feature; empty records are skipped).

    Raises
    ------
    InputError
        One line naming the file and the record: not UTF-8, malformed JSON, not a Feature,
        larger than ``ALPHAFENCE_MAX_JSON_MB``, or a malformed fence.
    """
    out = []
    for n, record in enumerate(_records(path)):
        try:
            doc = json.loads(record.decode("utf-8"))
        except UnicodeDecodeError as exc:
            raise InputError(path, f"not UTF-8 text ({exc.reason})", f"record {n}") from None
        except ValueError as exc:
            raise InputError(path, f"malformed JSON ({exc})", f"record {n}") from None
        kind = doc.get("type") if isinstance(doc, dict) else None
        if kind == "FeatureCollection" and isinstance(doc.get("features"), list):
            features = doc["features"]
        elif kind == "Feature":
            features = [doc]
        else:
            raise InputError(path, f"not a GeoJSON Feature ({kind!r})", f"record {n}")
        for feat in features:
            out.append(_feature(path, feat, len(out)))
    return _checked(path, out, "record")


def _feature(path, feat, i):
    props = feat.get("properties") if isinstance(feat, dict) else None
    if not isinstance(props, dict):
        raise InputError(path, "feature without properties", f"record {i}")
    label = f"record {i} ({props.get('site_id', '?')})"
    _kind_of(path, props, label)  # before the geometry, as fence_geojson checks them
    try:
        geom = shapely.geometry.shape(feat.get("geometry"))
    except (ShapelyError, ValueError, TypeError, AttributeError, KeyError, IndexError) as exc:
        raise InputError(path, f"malformed geometry ({exc})", label) from None
    return fence_record(path, props, geom, label, i)


def _records(path):
    """The records of a sequence as bytes, without separators; RS-separated when the file
    starts with RS, else one per line."""
    limit = max_json_bytes()
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    with fh:
        sep, pending, size, n = None, [], 0, 0
        while chunk := fh.read(CHUNK):
            if sep is None:
                sep = b"\x1e" if chunk[:1] == b"\x1e" else b"\n"
            parts = chunk.split(sep)
            for part in parts[:-1]:
                pending.append(part)
                record, pending, size = b"".join(pending), [], 0
                if record.strip():
                    yield record
                    n += 1
            pending.append(parts[-1])
            size += len(parts[-1])
            if size > limit:
                raise InputError(
                    path, "a record is larger than ALPHAFENCE_MAX_JSON_MB", f"record {n}"
                )
        record = b"".join(pending)
        if record.strip():
            yield record


def read_geoparquet(path) -> list:
    """The fences of a GeoParquet fence file (see ``fence_parquet``), a batch at a time.

    Raises
    ------
    InputError
        One line naming the file and the row that is malformed.
    MissingDependency
        pyarrow is not installed.
    """
    out = []
    for rows, geoms in fence_parquet.read_rows(path):
        for props, geom in zip(rows, geoms):
            i = len(out)
            label = f"row {i} ({props.get('site_id') or '?'})"
            out.append(fence_record(path, props, geom, label, i))
    return _checked(path, out, "row")
