"""``alphafence build --jobs``: chosen by the database's size when not given (``auto``), and the
fences are byte for byte the same whatever the number of workers."""

from unittest import mock

import pytest

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencing import tiled


def _build(tmp_path, database, name, *extra):
    out = tmp_path / name
    assert main(["build", str(database), "-o", str(out), "-q", *extra]) == 0
    return out.read_bytes()


@pytest.mark.parametrize("which", ["malta", "demo"])
def test_auto_jobs_writes_the_fences_of_one_job(which, request, tmp_path):
    database = request.getfixturevalue("malta") if which == "malta" else scene_path()
    one = _build(tmp_path, database, "one.geojson", "--jobs", "1")
    auto = _build(tmp_path, database, "auto.geojson")
    two = _build(tmp_path, database, "two.geojson", "--jobs", "2")
    assert len(one) > 1000
    assert auto == one
    assert two == one


def test_a_small_database_starts_no_worker_even_with_many_cores(malta, tmp_path):
    """Malta (432 restricted features, 3.7 MiB) is fenced in this process by default, on a
    machine of any number of cores; given --jobs 2 it starts workers."""
    with (
        mock.patch.object(tiled, "default_jobs", return_value=8),
        mock.patch.object(tiled, "run_processes", side_effect=AssertionError("workers")),
    ):
        _build(tmp_path, malta, "auto.geojson")
        with pytest.raises(AssertionError, match="workers"):
            _build(tmp_path, malta, "two.geojson", "--jobs", "2")


def test_a_large_database_uses_every_core():
    assert tiled.auto_jobs(tiled.AUTO_FEATURES, 1000, cores=3) == 3
    assert tiled.auto_jobs(tiled.AUTO_FEATURES - 1, 1000, cores=3) == 1
    assert tiled.auto_jobs(0, tiled.WARM_POOL_BYTES + 1, cores=3) == 3


def test_jobs_auto_is_said_and_taken(capsys):
    with pytest.raises(SystemExit):
        main(["build", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "(default: auto)" in help_text
    assert f"{tiled.AUTO_FEATURES:,} restricted features" in help_text
    assert f"{tiled.WARM_POOL_BYTES >> 20} MiB" in help_text
    assert main(["build", str(scene_path()), "-o", "/nonexistent/x.geojson", "--jobs", "0"]) == 2
