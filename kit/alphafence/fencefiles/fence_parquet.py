"""Fences as GeoParquet 1.1 (pyarrow, the ``parquet`` extra): the columns, a batch of GeoJSON
features encoded as a table, the ``geo`` metadata, and the rows read back.

One row per fence: the geometry as WKB in the column ``geometry`` (lon, lat; OGC:CRS84, so the
``geo`` metadata names no ``crs``), one column per property the kit always writes (``site_id``,
``name``, ``category``, ``kind``, ``method``, ``margin_m``, ``alt_min_m``, ``alt_max_m``,
``vertices``, ``area_m2``, ``sources`` as a list of strings) and every other property (a
circle's ``center`` and ``radius_m``, ``alpha_m``, ``repaired``, an ED-269 ``zone``) as one
JSON object in the string column ``extra`` (null when there is none). The build's meta is the
file's key-value metadata ``alphafence`` (JSON).
"""

from __future__ import annotations

import json

from alphafence.errors import InputError, MissingDependency, need

GEOMETRY = "geometry"
EXTRA = "extra"
# (name, arrow type name): the properties every fence has, in fence_properties' order
COLUMNS = (
    ("site_id", "string"),
    ("name", "string"),
    ("category", "string"),
    ("kind", "string"),
    ("method", "string"),
    ("margin_m", "float64"),
    ("alt_min_m", "float64"),
    ("alt_max_m", "float64"),
    ("vertices", "int64"),
    ("area_m2", "float64"),
    ("sources", "list<string>"),
)
NAMES = frozenset(name for name, _ in COLUMNS)
GEOPARQUET_VERSION = "1.1.0"


def _pyarrow(purpose):
    need(("pyarrow.parquet", purpose))
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not hasattr(pq.ParquetWriter, "add_key_value_metadata"):  # pyarrow < 17
        raise MissingDependency([("pyarrow", purpose, f"{pa.__version__} is installed")])
    return pa


def schema():
    """The Arrow schema of a fence GeoParquet file: the property columns, ``extra``, then
    ``geometry`` (binary WKB)."""
    pa = _pyarrow("writing GeoParquet")
    types = {"string": pa.string(), "float64": pa.float64(), "int64": pa.int64()}
    types["list<string>"] = pa.list_(pa.string())
    fields = [pa.field(name, types[kind]) for name, kind in COLUMNS]
    return pa.schema([*fields, pa.field(EXTRA, pa.string()), pa.field(GEOMETRY, pa.binary())])


def encode_table(features):
    """A batch of GeoJSON fence features as an Arrow table, with what the ``geo`` metadata
    needs to know of it.

    Parameters
    ----------
    features : list of dict
        GeoJSON Features (lon, lat) as ``fence_geojson`` makes them.

    Returns
    -------
    (pyarrow.Table, set of str, tuple or None)
        The rows, the GeoParquet geometry types seen (``"Polygon"``, ``"MultiPolygon Z"``),
        and their bounds ``(minx, miny, maxx, maxy)`` (None for no rows). All picklable.
    """
    from alphafence.fencefiles.fence_text import paused_gc

    pa = _pyarrow("writing GeoParquet")
    with paused_gc():  # many small lists and strings
        return _encode_table(pa, features)


def _encode_table(pa, features):
    import shapely

    from alphafence.fencefiles.fence_text import feature_geometries

    props = [f.get("properties") or {} for f in features]
    geoms = feature_geometries(features)
    columns = {name: [p.get(name) for p in props] for name, _ in COLUMNS}
    columns[EXTRA] = [_extra(p) for p in props]
    columns[GEOMETRY] = list(shapely.to_wkb(geoms)) if len(geoms) else []
    table = pa.Table.from_pydict(columns, schema=schema())
    types, bounds = set(), None
    if len(geoms):
        names = shapely.get_type_id(geoms)
        z = shapely.has_z(geoms)
        types = {_TYPE_NAMES[t] + (" Z" if has else "") for t, has in zip(names, z)}
        bounds = tuple(float(v) for v in shapely.total_bounds(geoms))
    return table, types, bounds


_TYPE_NAMES = {
    0: "Point",
    1: "LineString",
    2: "LineString",  # a LinearRing is written as a LineString
    3: "Polygon",
    4: "MultiPoint",
    5: "MultiLineString",
    6: "MultiPolygon",
    7: "GeometryCollection",
}


def _extra(props):
    rest = {k: v for k, v in props.items() if k not in NAMES}
    return _ENCODE(rest) if rest else None


_ENCODE = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False).encode  # json.dumps's


def union_bounds(a, b):
    """The bounds ``(minx, miny, maxx, maxy)`` covering both (either may be None).

    Examples
    --------
    >>> union_bounds((0, 0, 1, 1), (2, -1, 3, 0))
    (0, -1, 3, 1)
    """
    if a is None or b is None:
        return a if b is None else b
    return (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))


def geo_metadata(types, bounds) -> str:
    """The GeoParquet 1.1 ``geo`` file metadata for the ``geometry`` column.

    Parameters
    ----------
    types : set of str
        The geometry types written (an empty set: none written, the list is left empty).
    bounds : tuple or None
        ``(minx, miny, maxx, maxy)`` of every geometry written, or None for none.

    Examples
    --------
    >>> geo_metadata({"Polygon"}, (14.0, 35.8, 14.6, 36.1))
    '{"version":"1.1.0","primary_column":"geometry","columns":{"geometry":{"encoding":"WKB","geometry_types":["Polygon"],"bbox":[14.0,35.8,14.6,36.1]}}}'
    """
    column = {"encoding": "WKB", "geometry_types": sorted(types)}
    if bounds is not None:
        column["bbox"] = list(bounds)
    doc = {"version": GEOPARQUET_VERSION, "primary_column": GEOMETRY, "columns": {GEOMETRY: column}}
    return json.dumps(doc, separators=(",", ":"))


def read_rows(path, batch_rows: int = 65536):
    """The rows of a GeoParquet fence file, one row group batch at a time.

    Parameters
    ----------
    path : str or Path
    batch_rows : int, optional
        The most rows read at once.

    Yields
    ------
    (list of dict, numpy.ndarray)
        Per batch: the rows' properties (every column but the geometry, with ``extra``'s
        JSON object merged in) and their shapely geometries, lon/lat.

    Raises
    ------
    InputError
        One line: not a Parquet file, no GeoParquet ``geo`` metadata, a geometry column that
        is not WKB, malformed WKB or ``extra`` (naming the row).
    MissingDependency
        pyarrow is not installed.
    """
    import shapely
    from shapely.errors import ShapelyError

    _pyarrow(f"reading {path}")
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(path)
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (pa.ArrowException, OSError) as exc:
        raise InputError(path, f"not a Parquet file ({exc})") from None
    column = _primary_column(path, pf.schema_arrow.metadata or {})
    if column not in pf.schema_arrow.names:
        raise InputError(path, f"no geometry column {column!r}")
    row = 0
    for batch in pf.iter_batches(batch_size=batch_rows):
        data = batch.to_pydict()
        wkb = data.pop(column)
        try:
            geoms = shapely.from_wkb(wkb)
        except (ShapelyError, ValueError, TypeError) as exc:
            raise InputError(path, f"malformed WKB ({exc})", f"row {row}+") from None
        extra = data.pop(EXTRA, None)
        names = list(data)
        rows = []
        for i in range(len(wkb)):
            # a column the kit does not write (GDAL's conversion of a fence GeoJSON has one
            # per property) counts only where it holds a value, as a property would
            props = {n: data[n][i] for n in names if n in NAMES or data[n][i] is not None}
            if extra is not None and extra[i] is not None:
                props.update(_parse_extra(path, extra[i], row + i))
            rows.append(props)
        yield rows, geoms
        row += len(wkb)


def _primary_column(path, metadata):
    raw = metadata.get(b"geo")
    if raw is None:
        raise InputError(path, "not GeoParquet: no 'geo' file metadata")
    try:
        geo = json.loads(raw)
        column = geo["primary_column"]
        encoding = geo["columns"][column]["encoding"]
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(path, f"malformed GeoParquet 'geo' metadata ({exc!r})") from None
    if encoding != "WKB":
        raise InputError(path, f"geometry column {column!r} is {encoding}, only WKB is read")
    return column


def _parse_extra(path, text, row):
    try:
        extra = json.loads(text)
    except ValueError as exc:
        raise InputError(path, f"column 'extra' is not JSON ({exc})", f"row {row}") from None
    if not isinstance(extra, dict):
        raise InputError(path, "column 'extra' is not a JSON object", f"row {row}")
    return extra
