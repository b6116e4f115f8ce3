"""`alphafence build` at scale, end to end: worker processes and a Dask cluster (a scheduler and
two workers started here on loopback) write the very bytes one process writes; every streamed
output format holds the same fences; a bad feature deep in a streamed database stops the build
with one line and leaves nothing behind."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import shapely

from alphafence.cli import main
from alphafence.fencefiles.fence_read import read_fence_file

CLI = [sys.executable, "-m", "alphafence"]


def _build(args, tmp_path):
    return subprocess.run(
        [*CLI, "build", *args, "-q"], capture_output=True, text=True, timeout=600, cwd=tmp_path
    )


@pytest.fixture(scope="module")
def one_process(malta, tmp_path_factory):
    out = tmp_path_factory.mktemp("one") / "fences.geojson"
    assert main(["build", str(malta), "-o", str(out), "--jobs", "1", "-q"]) == 0
    return out


def test_worker_processes_write_what_one_process_writes(malta, one_process, tmp_path):
    out = tmp_path / "fences.geojson"
    res = _build([str(malta), "-o", str(out), "--jobs", "2"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes() == one_process.read_bytes()
    assert len(json.loads(out.read_text())["features"]) == 510


@pytest.mark.parametrize("suffix", [".geojsonl", ".geojsons", ".parquet"])
def test_every_streamed_format_holds_the_same_fences(malta, one_process, tmp_path, suffix):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"fences{suffix}"
    assert main(["build", str(malta), "-o", str(out), "--jobs", "2", "-q"]) == 0
    want = {(f.site_id, f.kind): f for f in read_fence_file(one_process)}
    got = {(f.site_id, f.kind): f for f in read_fence_file(out)}
    assert want.keys() == got.keys()
    for key, fence in want.items():
        # GeoJSON rounds to 1e-8 degrees; GeoParquet keeps every bit
        assert shapely.equals_exact(fence.geometry, got[key].geometry, 2e-8), key


def test_a_bad_feature_deep_in_a_stream_leaves_nothing_behind(tmp_path):
    db = tmp_path / "zones.geojsonl"
    good = {
        "type": "Feature",
        "properties": {"amenity": "hospital"},
        "geometry": {"type": "Point", "coordinates": [14.5, 35.9]},
    }
    lines = [json.dumps(dict(good, id=i)) for i in range(50_000)]
    lines[45_000] = json.dumps(
        {
            "type": "Feature",
            "id": 45_000,
            "properties": {"amenity": "hospital"},
            "geometry": {"type": "Point", "coordinates": [14.5, 135.9]},
        }
    )
    db.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out" / "fences.geojson"
    out.parent.mkdir()
    out.write_text("previous fences\n")
    res = _build([str(db), "-o", str(out)], tmp_path)
    assert res.returncode == 2
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and str(db) in err[0] and "feature/45000" in err[0], res.stderr
    assert out.read_text() == "previous fences\n"
    assert sorted(p.name for p in out.parent.iterdir()) == ["fences.geojson"]


def test_no_dask_scheduler_is_one_line(tmp_path, malta):
    pytest.importorskip("distributed")
    out = tmp_path / "fences.geojson"
    res = _build([str(malta), "-o", str(out), "--dask", "tcp://127.0.0.1:9"], tmp_path)
    assert res.returncode == 2
    assert len(res.stderr.strip().splitlines()) == 1 and "Dask" in res.stderr, res.stderr
    assert not out.exists() and not list(tmp_path.glob(".fences*"))


@pytest.fixture
def dask_cluster(tmp_path):
    """A Dask scheduler and two single-threaded worker processes on loopback, as an operator
    starts them on a cluster (`dask scheduler`, `dask worker`)."""
    distributed = pytest.importorskip("distributed")
    dask_cli = shutil.which("dask", path=str(Path(sys.executable).parent))
    if dask_cli is None:
        pytest.skip("the dask command is not installed beside this Python")
    info = tmp_path / "scheduler.json"
    procs = [
        subprocess.Popen(
            [
                dask_cli,
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--dashboard-address",
                ":0",
                "--scheduler-file",
                str(info),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        dask_cli,
                        "worker",
                        "--scheduler-file",
                        str(info),
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--host",
                        "127.0.0.1",
                        "--no-dashboard",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    cwd=tmp_path,
                )
            )
        with distributed.Client(scheduler_file=str(info), timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
            yield client.scheduler.address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def test_a_dask_cluster_writes_what_one_process_writes(malta, one_process, dask_cluster, tmp_path):
    out = tmp_path / "fences.geojson"
    res = _build([str(malta), "-o", str(out), "--dask", dask_cluster], tmp_path)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes() == one_process.read_bytes()


def test_progress_shows_counts_and_rate(monkeypatch):
    import io
    import re

    from rich.console import Console

    import alphafence.cli.common as common
    from alphafence.cli.build import phases

    buf = io.StringIO()
    monkeypatch.setattr(common, "err_console", Console(file=buf, force_terminal=True, width=120))
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    clock = iter(range(1000))  # one second per reading of the clock: rates without waiting
    with common.progress(True) as prog:
        prog.get_time = lambda: float(next(clock))
        for task in prog.tasks:
            task._get_time = prog.get_time
        update = phases(prog, "zones.geojsonl")
        for done in (0, 10_000, 40_000):
            update("reading", done, None)
        for done in (0, 10_000, 25_000):
            update("fencing", done, 40_000)
        prog.refresh()
        shown = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", buf.getvalue())
    assert "reading zones.geojsonl" in shown and "40000/?" in shown
    assert "fencing tiles" in shown and "25000/40000" in shown
    assert re.search(r"[\d,]+/s", shown)


def test_compile_and_the_monitor_take_the_streamed_formats(malta, one_process, tmp_path):
    pytest.importorskip("pyarrow")
    from alphafence.awareness.fenceset import FenceSet

    parquet, lines = tmp_path / "fences.parquet", tmp_path / "fences.geojsonl"
    assert main(["build", str(malta), "-o", str(parquet), "-q"]) == 0
    assert main(["build", str(malta), "-o", str(lines), "-q"]) == 0
    plans = {}
    for src in (one_process, parquet):
        out = tmp_path / f"{src.suffix[1:]}.plan"
        args = ["compile", str(src), "--bbox", "14.49,35.87,14.53,35.91", "-o", str(out)]
        assert main(args) == 0
        plans[src] = json.loads(out.read_text())["geoFence"]
    assert plans[one_process] == plans[parquet] and plans[parquet]["polygons"]
    want, got = FenceSet.from_geojson(one_process), FenceSet.from_geojson(lines)
    assert [r.site_id for r in want.records] == [r.site_id for r in got.records]
    assert shapely.equals_exact(want.local, got.local, 1e-6).all()


@pytest.mark.parametrize("name", ["parks.geojson", "parks.geojsonl"])
def test_a_database_that_adds_nothing_is_said(tmp_path, name):
    from alphafence.cli.demo import scene_path

    park = {
        "type": "Feature",
        "properties": {"leisure": "pitch"},
        "geometry": {"type": "Point", "coordinates": [14.5, 35.9]},
    }
    empty = tmp_path / name
    if name.endswith(".geojsonl"):
        empty.write_text(json.dumps(park) + "\n")
    else:
        empty.write_text(json.dumps({"type": "FeatureCollection", "features": [park]}))
    out = tmp_path / "fences.geojson"
    res = subprocess.run(
        [*CLI, "build", str(scene_path()), str(empty), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert f"{empty}: it holds no restricted features" in " ".join(res.stderr.split())


def test_the_spool_sits_beside_the_output(tmp_path, monkeypatch):
    # /tmp is often memory (tmpfs): a country's spooled features go on the output's disk
    import tempfile

    import alphafence.fencing.spool as spool
    from alphafence.cli.demo import scene_path

    dirs, original = [], tempfile.TemporaryFile

    def temporary_file(dir=None):
        dirs.append(dir)
        return original(dir=dir)

    monkeypatch.setattr(spool.tempfile, "TemporaryFile", temporary_file)
    out = tmp_path / "deep" / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(out), "-q", "--jobs", "1"]) == 0
    assert dirs == [str(out.parent)] and sorted(p.name for p in out.parent.iterdir()) == [
        "fences.geojson"
    ]
