"""Fences (and zones) written to a PostGIS table, for an OGC API server to serve to a fleet.

``postgresql://user@host:port/dbname/schema.table``: a libpq URL whose last path segment is
the table. The table is made when missing (geometry in EPSG:4326 with a GiST index, the
properties as columns, the whole properties as ``jsonb``, a ``version`` and an ``updated_at``
column) and its rows are replaced in one transaction: a reader sees the old fences or the new
ones, never half. Each write's ``version`` is one more than the last.
"""

from __future__ import annotations

import json
import re
from urllib.parse import urlsplit, urlunsplit

from alphafence.errors import InputError, need

SCHEMES = ("postgresql://", "postgres://")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,62}$")
COLUMNS = (  # fence properties kept as columns (the rest are in "properties")
    ("site_id", "text"), ("name", "text"), ("category", "text"), ("kind", "text"),
    ("method", "text"), ("margin_m", "double precision"), ("alt_min_m", "double precision"),
    ("alt_max_m", "double precision"), ("source_zone", "text"), ("source_hash", "text"),
)  # fmt: skip


def is_postgis_url(text) -> bool:
    """Whether an output names a PostGIS table.

    Examples
    --------
    >>> is_postgis_url("postgresql://fleet@db/zones/public.fences"), is_postgis_url("a.geojson")
    (True, False)
    """
    return str(text).lower().startswith(SCHEMES)


def split_target(url: str) -> tuple:
    """``(connection URL, schema, table)`` of a table URL; one line when it names none.

    Examples
    --------
    >>> split_target("postgresql://fleet@db:5432/zones/public.fences")
    ('postgresql://fleet@db:5432/zones', 'public', 'fences')
    >>> split_target("postgresql://fleet@db/zones/fences")
    ('postgresql://fleet@db/zones', 'public', 'fences')
    """
    parts = urlsplit(url)
    segments = [s for s in parts.path.split("/") if s]
    if len(segments) != 2:
        raise InputError(url, "a PostGIS output is postgresql://USER@HOST:PORT/DATABASE/"
                         "SCHEMA.TABLE")  # fmt: skip
    name = segments[1]
    schema, table = name.split(".", 1) if "." in name else ("public", name)
    for ident in (schema, table):
        if not _NAME.match(ident):
            raise InputError(url, f"{ident!r} is not a plain SQL name (letters, digits, _)")
    return urlunsplit(parts._replace(path="/" + segments[0])), schema, table


def write_features(url: str, features, meta: dict | None = None) -> int:
    """Replace the rows of the table ``url`` names with these Features (fences, or zones), in one
    transaction; the new ``version``. See :func:`write_feature_lines`.

    Parameters
    ----------
    url : str
        ``postgresql://.../DATABASE/SCHEMA.TABLE``.
    features : iterable of dict
        Fence GeoJSON Features (``alphafence build``'s).
    meta : dict, optional
        The build's metadata, kept in a table comment.

    Returns
    -------
    int
    """
    return write_feature_lines(url, (json.dumps(f) for f in features), meta)


def write_feature_lines(url: str, lines, meta: dict | None = None) -> int:
    """:func:`write_features` of Features given as JSON text, one per line (a GeoJSON lines
    file's, foreign members and all), streamed to PostgreSQL with ``COPY`` (any number, never
    all held) and parsed there; the new ``version``. ``meta`` is read once the lines are."""
    need(("psycopg", f"writing {url}"))
    import psycopg

    conninfo, schema, table = split_target(url)
    qualified = f'"{schema}"."{table}"'
    columns = ", ".join(f'"{c}" {t}' for c, t in COLUMNS)
    try:
        with psycopg.connect(conninfo) as conn, conn.transaction():
            conn.execute(f'CREATE SCHEMA IF NOT EXISTS "{schema}"')
            conn.execute(
                f"CREATE TABLE IF NOT EXISTS {qualified} (id text PRIMARY KEY, {columns}, "
                "properties jsonb NOT NULL, version integer NOT NULL, "
                "updated_at timestamptz NOT NULL DEFAULT now(), "
                "geom geometry(Geometry, 4326) NOT NULL)"
            )
            conn.execute(
                f'CREATE INDEX IF NOT EXISTS "{table}_geom" ON {qualified} USING gist (geom)'
            )
            row = conn.execute(f"SELECT coalesce(max(version), 0) FROM {qualified}").fetchone()
            version = int(row[0]) + 1
            conn.execute(f"DELETE FROM {qualified}")
            _copy(conn, qualified, lines, version)
            if meta:
                text = json.dumps(meta).replace("'", "''")
                conn.execute(f"COMMENT ON TABLE {qualified} IS '{text}'")
    except psycopg.Error as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(url, f"PostGIS refused the write, nothing changed: {message}") from None
    return version


def _copy(conn, qualified, lines, version, batch=2000):
    """Each Feature's JSON text ``COPY``'d into a staging table, then its row made by
    PostgreSQL: the properties as ``jsonb``, the columns from them, the geometry by
    ``ST_GeomFromGeoJSON``, the id ``SITE#KIND#N`` (the N-th of its site and kind, so the rows of
    one site are named alike whichever build or update wrote them)."""
    conn.execute("CREATE TEMP TABLE alphafence_staging (n bigserial, feature jsonb NOT NULL) "
                 "ON COMMIT DROP")  # fmt: skip
    with conn.cursor() as cur, cur.copy("COPY alphafence_staging (feature) FROM STDIN") as copy:
        chunk = []
        for line in lines:  # COPY's text format: a backslash is its escape (JSON has no tabs)
            chunk.append(line.strip().replace("\\", "\\\\"))
            if len(chunk) >= batch:
                copy.write("\n".join(chunk) + "\n")
                chunk = []
        if chunk:
            copy.write("\n".join(chunk) + "\n")
    names = ", ".join(f'"{c}"' for c, _ in COLUMNS)
    values = ", ".join(f"(p->>'{c}')::{t}" for c, t in COLUMNS)
    site = "coalesce(nullif(p->>'site_id', ''), 'fence')"
    kind = "coalesce(p->>'kind', 'None')"
    conn.execute(
        f"INSERT INTO {qualified} (id, {names}, properties, version, geom) "
        f"SELECT {site} || '#' || {kind} || '#' || "
        f"(row_number() OVER (PARTITION BY {site}, {kind} ORDER BY n) - 1), {values}, p, %s, "
        "ST_SetSRID(ST_GeomFromGeoJSON(feature->'geometry'), 4326) "
        "FROM (SELECT n, feature, feature->'properties' AS p FROM alphafence_staging) AS s",
        (version,),
    )
    conn.execute("DROP TABLE alphafence_staging")


def replace_rows(url: str, drop, features, meta_update: dict | None = None) -> tuple:
    """Replace the rows of the sites ``drop`` (site ids) in the table ``url`` names with these
    Features, in one transaction, at one more ``version`` than the table's.

    Parameters
    ----------
    url : str
    drop : set of str
    features : list of dict
    meta_update : dict, optional
        Merged into the table comment's metadata.

    Returns
    -------
    (int, int)
        Rows removed, and the new version.

    Raises
    ------
    InputError
        No such table, or PostGIS refused: nothing changed.
    """
    need(("psycopg", f"writing {url}"))
    import psycopg

    conninfo, schema, table = split_target(url)
    qualified = f'"{schema}"."{table}"'
    try:
        with psycopg.connect(conninfo) as conn, conn.transaction():
            if conn.execute("SELECT to_regclass(%s)", (qualified,)).fetchone()[0] is None:
                raise InputError(url, "no such table (build into it first)")
            conn.execute(f"LOCK TABLE {qualified} IN SHARE ROW EXCLUSIVE MODE")
            row = conn.execute(f"SELECT coalesce(max(version), 0) FROM {qualified}").fetchone()
            version = int(row[0]) + 1
            removed = conn.execute(
                f"DELETE FROM {qualified} WHERE site_id = ANY(%s)", (sorted(drop),)
            ).rowcount
            _copy(conn, qualified, (json.dumps(f) for f in features), version)
            if meta_update:
                old = conn.execute("SELECT obj_description(%s::regclass)", (qualified,)).fetchone()
                meta = {**json.loads(old[0] or "{}"), **meta_update}
                text = json.dumps(meta).replace("'", "''")
                conn.execute(f"COMMENT ON TABLE {qualified} IS '{text}'")
    except psycopg.Error as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(url, f"PostGIS refused the update, nothing changed: {message}") from None
    return removed, version
