"""Real servers for the live-source tests, started on loopback by the tests themselves.

* :func:`postgis` - Debian's PostgreSQL with PostGIS as an unprivileged cluster in a temporary
  folder (``initdb``, ``pg_ctl``; as root, run as the ``postgres`` user), trust auth on
  127.0.0.1 only.
* :func:`pygeoapi` - pygeoapi (from PyPI, in its own virtual environment ``.venv-pygeoapi``:
  ``make test`` makes it) serving one collection, from that PostGIS table or from a GeoJSON
  file (its file-backed provider).
* :class:`FaultProxy` (``tests/fault_proxy.py``) sits in front of pygeoapi to make it fail.

Where PostgreSQL or pygeoapi is missing the tests skip with one line (a failure under
``CI=true``: ``NO_POSTGIS`` and ``NO_PYGEOAPI`` are real parts, see ``conftest.py``).
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest

from .ci_env import under_ci

ROOT = Path(__file__).resolve().parents[1]
NO_POSTGIS = "PostgreSQL with PostGIS not found"
NO_PYGEOAPI = "pygeoapi not found"
START_S = 120.0  # a server on a loaded machine gets this long to answer its first request


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pg_bin():
    """The PostgreSQL server binaries with PostGIS beside them, or None."""
    for bindir in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True):
        version = Path(bindir).parent.name
        if os.path.exists(f"/usr/share/postgresql/{version}/extension/postgis.control"):
            return Path(bindir)
    return None


def postgis_missing() -> str | None:
    """Why PostGIS cannot run here (the skip line), or None (``ALPHAFENCE_HIDE_POSTGIS=1``
    hides it: the file-backed provider's run, tried on a machine that has it)."""
    if os.environ.get("ALPHAFENCE_HIDE_POSTGIS"):
        return f"{NO_POSTGIS} (hidden by ALPHAFENCE_HIDE_POSTGIS)"
    if _pg_bin() is None:
        return (f"{NO_POSTGIS} (Debian: apt-get install postgresql postgresql-15-postgis-3; "
                ".ci/run installs it)")  # fmt: skip
    if os.geteuid() == 0 and shutil.which("runuser") is None:
        return f"{NO_POSTGIS}: running as root without runuser to start it unprivileged"
    return None


class PostGIS:
    """A running cluster: :attr:`url` (``postgresql://alphafence@127.0.0.1:PORT/zones``)."""

    def __init__(self, folder: Path):
        self.bindir, self.folder = _pg_bin(), Path(folder)
        self.port = free_port()
        self.data = self.folder / "data"
        self.url = f"postgresql://alphafence@127.0.0.1:{self.port}/zones"
        self._as = []
        self.folder.mkdir(parents=True, exist_ok=True)
        self._own = None
        if os.geteuid() == 0:  # PostgreSQL refuses to run as root
            self._as = ["runuser", "-u", "postgres", "--"]
            # the cluster lives outside pytest's folders: a pytest session started by a test
            # (tests/test_ci_skips.py) makes /tmp/pytest-of-root private again, which would
            # shut the postgres user out of a cluster inside it
            self._own = Path(tempfile.mkdtemp(prefix="alphafence-pg-"))
            os.chmod(self._own, 0o711)
            self.folder = self._own / "pg"
            self.folder.mkdir()
            shutil.chown(self.folder, "postgres")
            self.data = self.folder / "data"

    def _run(self, *cmd, **kw):
        return subprocess.run([*self._as, *cmd], check=True, capture_output=True, text=True, **kw)

    def start(self) -> PostGIS:
        b = self.bindir
        self._run(str(b / "initdb"), "-D", str(self.data), "-U", "alphafence", "--auth=trust",
                  "-E", "UTF8", "--no-sync")  # fmt: skip
        opts = f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run(str(b / "pg_ctl"), "-D", str(self.data), "-o", opts, "-w", "-t", "120",
                  "-l", str(self.folder / "log"), "start")  # fmt: skip
        self._run(str(b / "createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U",
                  "alphafence", "zones")  # fmt: skip
        self.sql("CREATE EXTENSION postgis")
        return self

    def sql(self, text: str, *params):
        """Run one statement (psycopg, autocommit); the rows it returns, if any."""
        import psycopg

        with psycopg.connect(self.url, autocommit=True) as conn:
            cur = conn.execute(text, params or None)
            return cur.fetchall() if cur.description else None

    def stop(self) -> None:
        with contextlib.suppress(subprocess.CalledProcessError):
            self._run(str(self.bindir / "pg_ctl"), "-D", str(self.data), "-m", "immediate",
                      "-w", "stop")  # fmt: skip
        if self._own is not None:
            shutil.rmtree(self._own, ignore_errors=True)


def pygeoapi_bin() -> str | None:
    """pygeoapi's command: ``$ALPHAFENCE_PYGEOAPI`` (only it, when set), ``.venv-pygeoapi``,
    or PATH's."""
    given = os.environ.get("ALPHAFENCE_PYGEOAPI")
    if given is not None:
        return given if os.access(given, os.X_OK) else None
    for candidate in (os.environ.get("ALPHAFENCE_PYGEOAPI"),
                      str(ROOT / ".venv-pygeoapi" / "bin" / "pygeoapi"), shutil.which("pygeoapi")):  # fmt: skip
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    return None


def pygeoapi_missing() -> str | None:
    if pygeoapi_bin() is None:
        return f"{NO_PYGEOAPI} (make test installs it into .venv-pygeoapi)"
    return None


def postgres_provider(pg: PostGIS, table: str) -> dict:
    """pygeoapi's PostgreSQL provider over ``table`` (id ``id``, geometry ``geom``)."""
    return {
        "type": "feature",
        "name": "PostgreSQL",
        "data": {
            "host": "127.0.0.1",
            "port": pg.port,
            "dbname": "zones",
            "user": "alphafence",
            "password": "",
            "search_path": ["public"],
        },  # fmt: skip
        "id_field": "id",
        "table": table,
        "geom_field": "geom",
    }


def geojson_provider(path: Path) -> dict:
    """pygeoapi's file-backed GeoJSON provider over ``path``."""
    return {"type": "feature", "name": "GeoJSON", "data": str(path), "id_field": "id"}


class Pygeoapi:
    """pygeoapi serving one collection ``zones`` on loopback: :attr:`collection`."""

    def __init__(self, folder: Path, provider: dict):
        self.folder, self.provider = Path(folder), provider
        self.folder.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.collection = f"{self.url}/collections/zones"
        self.proc = None

    def start(self) -> Pygeoapi:
        import yaml

        config = {
            "server": {
                "bind": {"host": "127.0.0.1", "port": self.port},
                "url": self.url,
                "mimetype": "application/json; charset=UTF-8",
                "encoding": "utf-8",
                "languages": ["en-US"],
                "limits": {"default_items": 500, "max_items": 1000},
                "map": {
                    "url": "https://tile.openstreetmap.org/{z}/{x}/{y}.png",
                    "attribution": "OpenStreetMap",
                },  # fmt: skip
            },
            "logging": {"level": "ERROR"},
            "metadata": {
                "identification": {
                    "title": "AlphaFence test zones",
                    "description": "zones",
                    "keywords": ["zones"],
                    "terms_of_service": "none",
                    "url": self.url,
                },  # fmt: skip
                "license": {
                    "name": "CC0",
                    "url": "https://creativecommons.org/publicdomain/zero/1.0/",
                },
                "provider": {"name": "AlphaFence tests", "url": "http://127.0.0.1"},
                "contact": {
                    "name": "tests",
                    "position": "tests",
                    "address": "-",
                    "city": "-",
                    "stateorprovince": "-",
                    "postalcode": "-",
                    "country": "-",
                    "phone": "-",
                    "fax": "-",
                    "email": "-",
                    "url": "http://127.0.0.1",
                    "hours": "-",
                    "instructions": "-",
                    "role": "pointOfContact",
                },
            },
            "resources": {
                "zones": {
                    "type": "collection",
                    "title": "zones",
                    "description": "UAS geographical zones",
                    "keywords": ["zones"],
                    "extents": {
                        "spatial": {
                            "bbox": [-180, -90, 180, 90],
                            "crs": "http://www.opengis.net/def/crs/OGC/1.3/CRS84",
                        }
                    },  # fmt: skip
                    "providers": [self.provider],
                }
            },
        }
        cfg = self.folder / "pygeoapi.yml"
        cfg.write_text(yaml.safe_dump(config))
        exe = pygeoapi_bin()
        env = {**os.environ, "PYGEOAPI_CONFIG": str(cfg),
               "PYGEOAPI_OPENAPI": str(self.folder / "openapi.yml")}  # fmt: skip
        subprocess.run([exe, "openapi", "generate", str(cfg), "--output-file",
                        str(self.folder / "openapi.yml")], check=True, env=env,
                       capture_output=True)  # fmt: skip
        log = open(self.folder / "pygeoapi.log", "wb")
        # Flask's own server without pygeoapi serve's debug reloader (a second process)
        python = Path(exe).parent / "python"
        run = (f"from pygeoapi.flask_app import APP; APP.run(host='127.0.0.1', "
               f"port={self.port}, debug=False, threaded=True)")  # fmt: skip
        self.proc = subprocess.Popen([str(python), "-c", run], env=env, stdout=log, stderr=log,
                                     cwd=self.folder)  # fmt: skip
        deadline = time.monotonic() + START_S
        while True:
            try:
                with urllib.request.urlopen(f"{self.collection}?f=json", timeout=5) as r:
                    r.read()
                return self
            except OSError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    text = (self.folder / "pygeoapi.log").read_text(errors="replace")[-2000:]
                    raise RuntimeError(f"pygeoapi did not start:\n{text}") from None
                time.sleep(0.1)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


ZONES_TABLE = """
CREATE TABLE IF NOT EXISTS {table} (
    id text PRIMARY KEY,
    identifier text, name text, type text, reason text,
    "zoneAuthority" jsonb, "limitedApplicability" jsonb, "verticalLayer" jsonb,
    updated_at timestamptz NOT NULL DEFAULT now(),
    geom geometry(Geometry, 4326) NOT NULL
);
CREATE INDEX IF NOT EXISTS {table}_geom ON {table} USING gist (geom)
"""


class FileZones:
    """The zones as a GeoJSON file that pygeoapi's file-backed provider serves (it reads the
    file at every request): where PostgreSQL cannot be installed."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.path = self.folder / "zones.geojson"
        self._write([])

    def _features(self) -> list:
        import json

        return json.loads(self.path.read_text())["features"] if self.path.exists() else []

    def _write(self, features) -> None:
        import json

        if not features:  # no file: the provider's empty collection (an empty one it refuses)
            self.path.unlink(missing_ok=True)
            return
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
        os.replace(tmp, self.path)  # a request reads the old file or the new one, whole

    def insert(self, zone: dict) -> None:
        self._write([f for f in self._features() if f["id"] != zone["id"]] + [zone])

    def delete(self, ident: str) -> None:
        self._write([f for f in self._features() if f["id"] != ident])

    def clear(self) -> None:
        self._write([])


def clear_zones(store, table: str) -> None:
    """Every zone gone from the table (or file)."""
    if isinstance(store, FileZones):
        store.clear()
    else:
        store.sql(f"DELETE FROM {table}")


def delete_zone(store, table: str, ident: str) -> None:
    """One zone gone from the table (or file)."""
    if isinstance(store, FileZones):
        store.delete(ident)
    else:
        store.sql(f"DELETE FROM {table} WHERE id = %s", ident)


def insert_zone(pg, table: str, zone: dict) -> None:
    """Insert (or replace) one ED-318 zone Feature into the zones table (or file)."""
    import json

    if isinstance(pg, FileZones):
        pg.insert(zone)
        return
    p = zone["properties"]
    pg.sql(
        f"INSERT INTO {table} (id, identifier, name, type, reason, \"zoneAuthority\", "
        "\"limitedApplicability\", \"verticalLayer\", geom) VALUES (%s, %s, %s, %s, %s, %s, %s, "
        "%s, ST_SetSRID(ST_GeomFromGeoJSON(%s), 4326)) ON CONFLICT (id) DO UPDATE SET "
        "name = EXCLUDED.name, type = EXCLUDED.type, \"limitedApplicability\" = "
        "EXCLUDED.\"limitedApplicability\", geom = EXCLUDED.geom, updated_at = now()",
        zone["id"], p["identifier"], p.get("name"), p["type"], p.get("reason"),
        json.dumps(p.get("zoneAuthority")), json.dumps(p.get("limitedApplicability")),
        json.dumps(p.get("verticalLayer")), json.dumps(zone["geometry"]),
    )  # fmt: skip


def ed318_zone(ident, ring, name=None, window=None, kind="PROHIBITED"):
    """An ED-318 zone Feature over the lon/lat ``ring`` (upper limit 120 m AGL)."""
    props = {
        "identifier": ident,
        "name": name or ident,
        "type": kind,
        "reason": "EMERGENCY",
        "zoneAuthority": [{"name": "AlphaFence test authority", "purpose": "AUTHORIZATION"}],
        "verticalLayer": {
            "upper": 120,
            "upperReference": "AGL",
            "lower": 0,
            "lowerReference": "AGL",
            "uom": "m",
        },  # fmt: skip
    }
    if window is not None:
        props["limitedApplicability"] = window
    return {"type": "Feature", "id": ident, "properties": props,
            "geometry": {"type": "Polygon", "coordinates": [list(map(list, ring))]}}  # fmt: skip


def python() -> str:
    return sys.executable


@contextlib.contextmanager
def serving(folder: Path):
    """``(store, Pygeoapi, table)``: an empty ED-318 zones table (PostGIS) served as the OGC
    API collection ``zones``; both stopped at the end. Without PostgreSQL the zones are a file
    served by pygeoapi's file-backed provider instead, and a warning says so (under ``CI=true``
    that is a failure: the skip line names PostgreSQL); without pygeoapi the test is skipped."""
    if pygeoapi_missing():
        pytest.skip(pygeoapi_missing())
    no_pg = postgis_missing()
    if no_pg and under_ci():
        pytest.skip(no_pg)
    if no_pg:
        import warnings

        warnings.warn(f"{no_pg}: the live-source tests run against pygeoapi's file-backed "
                      "provider", stacklevel=2)  # fmt: skip
        store = FileZones(folder / "zones")
        provider = geojson_provider(store.path)
    else:
        store = PostGIS(folder / "pg").start()
        provider = postgres_provider(store, "zones")
    api = None
    try:
        if isinstance(store, PostGIS):
            for statement in ZONES_TABLE.format(table="zones").split(";"):
                store.sql(statement)
        api = Pygeoapi(folder / "api", provider).start()
        yield store, api, "zones"
    finally:
        if api is not None:
            api.stop()
        if isinstance(store, PostGIS):
            store.stop()


@pytest.fixture
def live_source(tmp_path):
    """A zones table served for one test (:func:`serving`)."""
    with serving(tmp_path) as servers:
        yield servers


@pytest.fixture(scope="module")
def shared_source(tmp_path_factory):
    """A zones table served for a module's tests (each empties it first)."""
    with serving(tmp_path_factory.mktemp("source")) as servers:
        yield servers
