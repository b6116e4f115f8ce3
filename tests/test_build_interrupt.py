"""Ctrl-C during a parallel build: exit 130, nothing written, and one line on the terminal (no
traceback from the forkserver or any worker: they leave Ctrl-C to the main process, which
cancels the jobs not started), whether it comes while the forkserver is still importing or
while the workers fence. The build and its processes get SIGINT as a terminal
sends it, to the whole process group; each moment is an event seen in the process table."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.synth_db import main as synth_main


def children(pid):
    """The command lines of ``pid``'s descendants."""
    out = subprocess.run(["ps", "-eww", "-o", "pid=,ppid=,args="], capture_output=True, text=True)
    rows = [line.split(None, 2) for line in out.stdout.splitlines()]
    tree, found, grew = {str(pid)}, [], True
    while grew:  # any depth (an interpreter started through a wrapper is one more level)
        grew = False
        for p, pp, args in (r for r in rows if len(r) == 3):
            if pp in tree and p not in tree:
                tree.add(p)
                found.append(args)
                grew = True
    return found


@pytest.fixture(scope="module")
def database(tmp_path_factory, malta):
    path = tmp_path_factory.mktemp("db") / "db.geojsonl"
    synth_main(["20000", str(path), "--extract", str(malta)])
    return path


@pytest.mark.parametrize("moment", ["importing", "fencing"])
def test_ctrl_c_stops_a_parallel_build_with_one_line(database, tmp_path, moment):
    out = tmp_path / "f.geojson"
    argv = [
        sys.executable,
        "-m",
        "alphafence",
        "build",
        str(database),
        "-o",
        str(out),
        "--jobs",
        "2",
    ]
    build = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)  # fmt: skip
    # the moment: the forkserver exists (still importing), or it has forked its workers
    want = 1 if moment == "importing" else 3
    deadline = time.monotonic() + 120
    while sum("forkserver" in c for c in children(build.pid)) < want:
        assert build.poll() is None and time.monotonic() < deadline, "no worker processes"
        time.sleep(0.01)
    os.killpg(build.pid, signal.SIGINT)
    stdout, stderr = build.communicate(timeout=60)
    assert build.returncode == 130, stderr
    assert [line for line in stderr.splitlines() if line.strip()] == ["alphafence: interrupted"]
    assert not out.exists() and not list(Path(tmp_path).iterdir())


def test_a_ctrl_c_while_the_forkserver_starts_is_raised_not_lost(monkeypatch):
    """The window in which the main process ignores Ctrl-C (so that the forkserver starts
    ignoring it): a Ctrl-C that comes then is held and raised once the handler is back, and
    the forkserver it had started is stopped. Before, such a Ctrl-C was lost and the build ran
    on to the end (seen in CI: exit 0 for a Ctrl-C sent as the forkserver appeared)."""
    import threading
    from multiprocessing import forkserver

    from alphafence.fencing import tile_jobs

    assert threading.current_thread() is threading.main_thread()
    started = []
    real = forkserver.ensure_running

    def ensure_running_then_ctrl_c():
        real()
        started.append(forkserver._forkserver._forkserver_pid)
        # a terminal's Ctrl-C, inside the window, to the thread that builds (a pytest worker
        # has a thread of its own beside it, which a signal to the process could reach)
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    monkeypatch.setattr(forkserver, "ensure_running", ensure_running_then_ctrl_c)
    # Python's own handler, as the command has (a pytest worker has one of its own)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            tile_jobs.start_pool(2)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)
    assert started, "the forkserver was not started"
    with pytest.raises(ProcessLookupError):  # killed and reaped
        os.kill(started[0], 0)
    assert forkserver._forkserver._forkserver_pid is None  # the next pool starts a new one
    monkeypatch.setattr(forkserver, "ensure_running", real)
    pool = tile_jobs.start_pool(1)
    try:
        assert pool.submit(int, "7").result() == 7
    finally:
        tile_jobs.stop_pool(pool, server=True)
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())
