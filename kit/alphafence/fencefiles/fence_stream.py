"""Fence outputs written as a build's tiles complete, all or nothing.

The format is chosen by the output's suffix (:func:`writer_for`): ``.geojson`` and ``.json``
the kit's fence GeoJSON FeatureCollection, byte for byte what ``fence_geojson`` writes for the
same fences and meta; ``.geojsonl`` newline-delimited GeoJSON (one Feature per line);
``.geojsons`` and ``.geojsonseq`` an RFC 8142 GeoJSON text sequence (RS, a Feature, LF per
record; GDAL's GeoJSONSeq driver reads both kinds); ``.parquet`` GeoParquet 1.1 with WKB
geometry (pyarrow, the ``parquet`` extra; columns in ``fence_parquet``).

In a sequence every record is a Feature, so GDAL counts exactly the fences and line tools
(``jq``, ``wc -l``) see one fence per record; the build's meta rides as foreign members
(``"generator"``, ``"alphafence"``) on the first record only (an empty build writes an empty
file, without meta). In GeoParquet it is the file metadata ``alphafence``.

The work is split for a pool: :meth:`FenceWriter.encode` turns a batch of GeoJSON Features
(as ``fence_geojson`` makes them) into something picklable, in any process; the process that
owns the output passes it to :meth:`FenceWriter.write`. Each output is written to a temporary
sibling (``.NAME.XXXX.tmp``) and renamed into place on :meth:`FenceWriter.commit`, after an
fsync; on :meth:`FenceWriter.abort`, or an exception inside ``with``, the temporary file is
removed and whatever was at the path is left as it was. :func:`open_writers` does that for
several outputs at once: none is renamed until every one is complete.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from alphafence import __version__
from alphafence.errors import InputError
from alphafence.fencefiles import fence_parquet
from alphafence.fencefiles.atomic import temp_beside
from alphafence.fencefiles.fence_text import feature_texts

RS = b"\x1e"
GENERATOR = f"alphafence {__version__}"  # as fence_geojson writes it


def _dumps(obj) -> str:
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False)


class _AllOrNothing:
    """As a context manager: commit on success, abort on an exception."""

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
        else:
            self.abort()
        return False


class FenceWriter(_AllOrNothing):
    """One fence output being written: a temporary sibling of ``path`` until committed.

    Parameters
    ----------
    path : str or Path
        Where the output goes (parent folders are made as needed).
    meta : dict, optional
        What the build was made of (``build.outputs.build_meta``).

    Attributes
    ----------
    suffixes : tuple of str
        The suffixes this format is chosen for.
    records : int
        Features written so far.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> feature = {"type": "Feature", "properties": {"kind": "keep_out"}, "geometry": None}
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     out = pathlib.Path(folder) / "fences.geojsonl"
    ...     with writer_for(out)(out, {"method": "alpha"}) as writer:
    ...         writer.write(writer.encode([feature]))
    ...     print(out.read_text(encoding="utf-8"), end="")
    {"type":"Feature","generator":"alphafence ...","alphafence":{"method":"alpha"},"properties":{"kind":"keep_out"},"geometry":null}
    """

    suffixes: tuple = ()

    def __init__(self, path, meta: dict | None = None):
        self.path = Path(path)
        self.meta = dict(meta or {})
        self.records = 0
        self.state = "open"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_beside(self.path)  # a new file's permissions, not mkstemp's 0600
        self.tmp = Path(tmp)
        self._fh = os.fdopen(fd, "wb")
        try:
            self._start()
        except BaseException:
            self.abort()
            raise

    @staticmethod
    def encode(features: list) -> object:
        """A batch of GeoJSON fence Features encoded for :meth:`write` (picklable; runs in any
        process)."""
        raise NotImplementedError

    def write(self, encoded) -> None:
        """Append a batch that :meth:`encode` made."""
        self._check("open")
        self._write(encoded)

    def finish(self) -> None:
        """Complete the temporary file (footer, flush, fsync) without renaming it yet."""
        self._check("open")
        try:
            self._end()
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
        except BaseException:
            self.abort()
            raise
        self.state = "finished"

    def publish(self) -> None:
        """Rename the finished temporary file onto the path."""
        self._check("finished")
        try:
            os.replace(self.tmp, self.path)
        except BaseException:
            self.abort()
            raise
        self.state = "committed"

    def commit(self) -> None:
        """Finish the output and rename it into place (fsync first)."""
        self.finish()
        self.publish()

    def abort(self) -> None:
        """Remove the temporary file; the path keeps what it had. Safe to call twice."""
        if self.state in ("committed", "aborted"):
            return
        self.state = "aborted"
        self._close_quietly()
        try:
            self._fh.close()
        except Exception:  # noqa: BLE001 - a failed flush of an output being thrown away
            pass
        try:
            os.unlink(self.tmp)
        except FileNotFoundError:
            pass

    def _check(self, state):
        if self.state != state:
            raise ValueError(f"{self.path}: the writer is {self.state}, not {state}")

    def _start(self):
        pass

    def _write(self, encoded):
        raise NotImplementedError

    def _end(self):
        pass

    def _close_quietly(self):
        pass


class GeoJSONWriter(FenceWriter):
    """The kit's fence GeoJSON FeatureCollection, written as header, features, footer."""

    suffixes = (".geojson", ".json")

    @staticmethod
    def encode(features: list) -> tuple:
        """``(count, bytes)``: the features as compact JSON, comma-separated."""
        return len(features), ",".join(feature_texts(features)).encode("utf-8")

    def _start(self):
        head = f'{{"type":"FeatureCollection","generator":{_dumps(GENERATOR)},'
        if self.meta:  # as fence_geojson: no "alphafence" member for an empty meta
            head += f'"alphafence":{_dumps(self.meta)},'
        self._fh.write((head + '"features":[').encode("utf-8"))

    def _write(self, encoded):
        count, data = encoded
        if not count:
            return
        if self.records:
            self._fh.write(b",")
        self._fh.write(data)
        self.records += count

    def _end(self):
        self._fh.write(b"]}\n")


class GeoJSONLinesWriter(FenceWriter):
    """Newline-delimited GeoJSON: one Feature per line, the meta on the first."""

    suffixes = (".geojsonl",)
    separator = b""

    @staticmethod
    def encode(features: list) -> tuple:
        """``(count, bytes)``: one Feature per line."""
        return len(features), "".join(t + "\n" for t in feature_texts(features)).encode("utf-8")

    def _write(self, encoded):
        count, data = encoded
        if not count:
            return
        if not self.records:  # the meta, as foreign members of the first Feature
            start = len(self.separator) + 1
            members = f'"generator":{_dumps(GENERATOR)},'
            if self.meta:
                members += f'"alphafence":{_dumps(self.meta)},'
            if data.startswith(self.separator + b'{"type":"Feature",'):
                start = len(self.separator) + len(b'{"type":"Feature",')
            elif data[start : start + 1] == b"}":  # an empty object: no comma after the meta
                members = members[:-1]
            data = data[:start] + members.encode("utf-8") + data[start:]
        self._fh.write(data)
        self.records += count


class GeoJSONSeqWriter(GeoJSONLinesWriter):
    """RFC 8142 GeoJSON text sequence: each record RS, a Feature, LF; the meta on the first."""

    suffixes = (".geojsons", ".geojsonseq")
    separator = RS

    @staticmethod
    def encode(features: list) -> tuple:
        """``(count, bytes)``: one RS-prefixed, LF-terminated record per Feature."""
        text = "".join("\x1e" + t + "\n" for t in feature_texts(features))
        return len(features), text.encode("utf-8")


class GeoParquetWriter(FenceWriter):
    """GeoParquet 1.1 (WKB), written in row groups of up to ``row_group_rows`` fences."""

    suffixes = (".parquet",)
    row_group_rows = 65536

    @staticmethod
    def encode(features: list) -> tuple:
        """``(table, geometry types, bounds)`` (see ``fence_parquet.encode_table``)."""
        return fence_parquet.encode_table(features)

    def _start(self):
        schema = fence_parquet.schema()  # first: says in one line if pyarrow is missing
        import pyarrow.parquet as pq

        self._writer = pq.ParquetWriter(self._fh, schema, store_schema=False)
        self._pending, self._rows = [], 0
        self._types, self._bounds = set(), None

    def _write(self, encoded):
        table, types, bounds = encoded
        if not table.num_rows:
            return
        self._types |= set(types)
        self._bounds = fence_parquet.union_bounds(self._bounds, bounds)
        self._pending.append(table)
        self._rows += table.num_rows
        self.records += table.num_rows
        if self._rows >= self.row_group_rows:
            self._flush()

    def _flush(self):
        import pyarrow as pa

        if self._pending:
            table = pa.concat_tables(self._pending)
            self._writer.write_table(table, row_group_size=max(table.num_rows, 1))
        self._pending, self._rows = [], 0

    def _end(self):
        self._flush()
        metadata = {"geo": fence_parquet.geo_metadata(self._types, self._bounds)}
        if self.meta:
            metadata["alphafence"] = _dumps(self.meta)
        self._writer.add_key_value_metadata(metadata)
        self._writer.close()

    def _close_quietly(self):
        writer = getattr(self, "_writer", None)
        if writer is not None:
            try:
                writer.close()
            except Exception:  # noqa: BLE001 - the output is being thrown away
                pass


WRITERS = (GeoJSONWriter, GeoJSONLinesWriter, GeoJSONSeqWriter, GeoParquetWriter)


def writer_for(path) -> type:
    """The writer class for an output path, by its suffix (case ignored).

    Raises
    ------
    InputError
        One line naming the path and the suffixes known.

    Examples
    --------
    >>> writer_for("out/fences.parquet").__name__
    'GeoParquetWriter'
    >>> writer_for("fences.kml")
    Traceback (most recent call last):
    ...
    alphafence.errors.InputError: fences.kml: unknown fence output format '.kml' (use .geojson, .json, .geojsonl, .geojsons, .geojsonseq or .parquet)
    """
    suffix = Path(path).suffix.lower()
    for cls in WRITERS:
        if suffix in cls.suffixes:
            return cls
    known = [s for cls in WRITERS for s in cls.suffixes]
    said = f"{', '.join(known[:-1])} or {known[-1]}"
    raise InputError(path, f"unknown fence output format {suffix or '(none)'!r} (use {said})")


class FenceWriters(_AllOrNothing, list):
    """Several outputs written together, committed all or nothing (:func:`open_writers`).

    As a context manager: :meth:`commit` on success, :meth:`abort` on an exception.
    """

    def write(self, encoded: list) -> None:
        """Append one batch to every output: ``encoded[i]`` was made by writer i's ``encode``."""
        for writer, batch in zip(self, encoded, strict=True):
            writer.write(batch)

    def encoders(self) -> list:
        """Each output's ``encode`` (static, picklable), in order, for worker processes."""
        return [type(w).encode for w in self]

    def commit(self) -> None:
        """Finish every output, then rename them all; if any fails to finish, none is renamed
        and every temporary file is removed."""
        try:
            for writer in self:
                writer.finish()
            for writer in self:
                writer.publish()
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Remove every temporary file not yet renamed."""
        for writer in self:
            writer.abort()


def open_writers(paths, meta: dict | None = None) -> FenceWriters:
    """Open a writer for each path (by suffix), to be committed all or nothing.

    Parameters
    ----------
    paths : list of str or Path
    meta : dict, optional
        The build's meta, stored in every output.

    Returns
    -------
    FenceWriters
        A list of writers, in the order of ``paths``.

    Raises
    ------
    InputError
        An unknown suffix, or a path named twice (checked before any file is opened).
    """
    classes, seen = [], set()
    for path in paths:
        classes.append(writer_for(path))
        key = os.path.abspath(path)
        if key in seen:
            raise InputError(path, "named twice as a fence output")
        seen.add(key)
    writers = FenceWriters()
    try:
        for cls, path in zip(classes, paths):
            writers.append(cls(path, meta))
    except BaseException:
        writers.abort()
        raise
    return writers
