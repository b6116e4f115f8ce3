"""Where an update writes: the fence file the build wrote (GeoJSON, GeoJSON lines or text
sequence, GeoParquet), rewritten beside and moved over, or the PostGIS table, changed in one
transaction. Either way a reader sees the fences before the update or after it, never half,
and the rows of sites the update did not touch are kept as they were, byte for byte."""

from __future__ import annotations

import json
from pathlib import Path

from alphafence.errors import InputError
from alphafence.fencefiles.fence_stream import GeoParquetWriter, _dumps, writer_for
from alphafence.sources.postgis import is_postgis_url


def replace_sites(target, drop, features, meta_update) -> dict:
    """Replace the fences of the sites ``drop`` (site ids) with ``features``.

    Parameters
    ----------
    target : str
        A fence file, or ``postgresql://.../SCHEMA.TABLE``.
    drop : set of str
        Site ids whose rows go.
    features : list of dict
        GeoJSON fence Features (``fence_geojson.fence_features``).
    meta_update : dict
        Merged into the output's ``alphafence`` metadata.

    Returns
    -------
    dict
        ``{"removed": rows, "added": rows, "version": int or None}``.
    """
    if is_postgis_url(target):
        from alphafence.sources.postgis import replace_rows

        removed, version = replace_rows(target, drop, features, meta_update)
        return {"removed": removed, "added": len(features), "version": version}
    path = Path(target)
    if not path.is_file():
        raise InputError(path, "no such fence file (the update needs the build's output)")
    writer = writer_for(path)
    if writer is GeoParquetWriter:
        removed = _parquet(path, drop, features, meta_update)
    else:
        removed = _text(path, writer, drop, features, meta_update)
    return {"removed": removed, "added": len(features), "version": None}


def _text(path, writer, drop, features, meta_update):
    from alphafence.fencefiles.fence_text import feature_texts

    raw = path.read_bytes()
    if writer.suffixes[0] == ".geojson":
        try:
            doc = json.loads(raw)
            records = doc["features"]
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(path, f"not a fence GeoJSON file ({exc})") from None
        meta = doc.get("alphafence") or {}
        texts = feature_texts(records)
    else:
        lines = [line.strip(b"\x1e\r\n ") for line in raw.split(b"\n")]
        lines = [line for line in lines if line]
        records, meta = [], {}
        for k, line in enumerate(lines):
            try:
                record = json.loads(line)
            except ValueError as exc:
                raise InputError(path, f"line {k + 1} is not JSON ({exc})") from None
            if k == 0:  # the meta the writer put on the first record comes off, as it went on
                meta = record.get("alphafence") or {}
                members = f'"generator":{_dumps(record.get("generator"))},'
                if "alphafence" in record:
                    members += f'"alphafence":{_dumps(record["alphafence"])},'
                lines[0] = line.replace(members.encode("utf-8"), b"", 1)
            records.append(record)
        texts = [line.decode("utf-8") for line in lines]
    keep = [t for t, r in zip(texts, records) if _site(r) not in drop]
    meta = {**meta, **meta_update}
    with writer(path, meta) as out:
        if keep:
            out.write(_encoded(writer, keep))
        if features:
            out.write(writer.encode(features))
    return len(texts) - len(keep)


def _encoded(writer, texts):
    if writer.suffixes[0] == ".geojson":
        return len(texts), ",".join(texts).encode("utf-8")
    prefix = "\x1e" if writer.suffixes[0] == ".geojsons" else ""
    return len(texts), "".join(prefix + t + "\n" for t in texts).encode("utf-8")


def _site(record):
    return (record.get("properties") or {}).get("site_id")


def _parquet(path, drop, features, meta_update):
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq
    import shapely

    from alphafence.fencefiles import fence_parquet

    try:
        table = pq.read_table(path, schema=fence_parquet.schema())
        old_meta = pq.read_metadata(path).metadata or {}
    except (pa.ArrowException, OSError) as exc:
        raise InputError(path, f"not a fence GeoParquet file ({exc})") from None
    meta = json.loads(old_meta.get(b"alphafence", b"{}") or b"{}")
    gone = pc.is_in(table["site_id"], value_set=pa.array(sorted(drop), pa.string()))
    kept = table.filter(pc.invert(pc.fill_null(gone, False)))
    geoms = shapely.from_wkb(kept[fence_parquet.GEOMETRY].to_numpy(zero_copy_only=False))
    types, bounds = set(), None
    if len(geoms):
        names, z = shapely.get_type_id(geoms), shapely.has_z(geoms)
        types = {fence_parquet._TYPE_NAMES[t] + (" Z" if h else "") for t, h in zip(names, z)}
        bounds = tuple(float(v) for v in shapely.total_bounds(geoms))
    with GeoParquetWriter(path, {**meta, **meta_update}) as out:
        out.write((kept, types, bounds))
        if features:
            out.write(GeoParquetWriter.encode(features))
    return table.num_rows - kept.num_rows
