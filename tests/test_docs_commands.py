"""Every command the docs show is run, so no page tells a user to type something that fails.

A page's fenced blocks are read in order:

- ```` ```console ```` blocks: each ``$ `` line (with ``\\`` continuation lines) is a command;
  the other lines are what it prints, shown for the reader and not compared.
- ```` ```bash ````, ```` ```sh ```` and ```` ```shell ```` blocks: every line that is not blank
  or a comment is a command.
- ```` ```python ```` blocks: run as one script.

Each command runs with ``bash -c`` in a temporary directory of the page's own (the commands of
one page share it, in order, so a page builds what its later commands read), with the kit's
``alphafence`` first on PATH, and must exit 0. An HTML comment on the line before a block says
otherwise:

- ``<!-- not-run: REASON -->``: shown, not run (a network download, a real device, root on a
  Pi). The reason is required; the Navio2 page's ``<!-- navio2-install: SUITE -->`` and
  ``<!-- navio2-service -->`` blocks count as not run here (``make navio2-test`` runs the
  install blocks in a Debian armhf userland: ``tests/navio2/readme.py``).
- ``<!-- docs-test: OPTION ... -->`` with any of
  ``exit=N`` (the block's last command exits N; those before it 0),
  ``sitl`` (needs ArduPilot SITL: without a binary the page's other blocks run and the test
  is skipped at the end, naming how many blocks were not run),
  ``background="TEXT"`` (the command keeps running, as SITL and the monitor do until Ctrl-C:
  it is started, must print TEXT, and is stopped with SIGINT once the page's blocks have run;
  it must then exit 0, or 130 as socat does on Ctrl-C),
  ``needs=PROGRAM`` (skipped, and counted, when PROGRAM is not on PATH),
  ``unprivileged`` (a server that refuses root, PostgreSQL's: run as the ``postgres`` user
  when the tests run as root).

A command ending in ``&`` runs in the background, as a shell runs it: the next command starts
at once, and a later ``wait`` waits for every such command, each of which must exit 0.

The directory holds, before the first block, the files the pages say come from elsewhere:
:data:`GIVEN`. A block of another language (``text``, ``toml``, ``json``) is never run and
must hold no ``$ `` command line.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from .conftest import MALTA  # ../shared's, or $ALPHAFENCE_SHARED's

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BIN = Path(sys.executable).parent
PYGEOAPI = ROOT / ".venv-pygeoapi" / "bin"

RUN = {"console", "bash", "sh", "shell", "python"}
COMMAND_TIMEOUT_S = 300
READY_TIMEOUT_S = 240
_FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
_MARKER = re.compile(r"^<!--\s*([a-z0-9-]+)\s*(?::\s*(.*?))?\s*-->$")
_NAVIO2 = {
    "navio2-install": "make navio2-test runs it in a Debian armhf userland",
    "navio2-service": "needs systemd on the Pi",
}


@dataclass
class Block:
    """One fenced block of a page, its commands and what its marker asks."""

    page: str
    line: int
    lang: str
    text: str
    not_run: str | None = None
    options: dict = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"docs/{self.page} line {self.line}"

    def commands(self) -> list[str]:
        """The block's commands, continuation lines joined."""
        if self.lang == "python":
            return [self.text]
        lines = self.text.splitlines()
        if self.lang == "console":
            out, current = [], None
            for line in lines:
                if current is not None:
                    current += "\n" + line
                elif line.startswith("$ "):
                    current = line[2:]
                else:
                    continue
                if not current.endswith("\\"):
                    out.append(current)
                    current = None
            if current is not None:
                out.append(current)
            return out
        out, current = [], ""
        for line in lines:
            current += line
            if current.endswith("\\"):
                current += "\n"
                continue
            if current.strip() and not current.lstrip().startswith("#"):
                out.append(current)
            current = ""
        return out


def _options(text: str, where: str) -> dict:
    options = {}
    for word in shlex.split(text or ""):
        key, eq, value = word.partition("=")
        if key not in ("exit", "sitl", "background", "needs", "timeout", "unprivileged") or (
            bool(eq) == (key in ("sitl", "unprivileged"))
        ):
            raise ValueError(f"{where}: docs-test option {word!r} not understood")
        options[key] = value if eq else True
    return options


def parse(page: str, text: str) -> list[Block]:
    """The fenced blocks of ``text`` (a page of docs/), each with its marker's meaning.

    Raises ValueError on a marker it does not understand, a not-run without a reason, or a
    block never closed.
    """
    lines = text.splitlines()
    blocks, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, lang = m.group(1), m.group(2)
        end = next((k for k in range(i + 1, len(lines)) if lines[k].strip() == "```"), None)
        if end is None:
            raise ValueError(f"docs/{page} line {i + 1}: code block never closed")
        body = "\n".join(x[len(indent) :] for x in lines[i + 1 : end]) + "\n"
        block = Block(page, i + 1, lang, body)
        before = next((lines[k].strip() for k in range(i - 1, -1, -1) if lines[k].strip()), "")
        marker = _MARKER.match(before)
        if marker:
            name, value = marker.group(1), marker.group(2)
            if name == "not-run":
                if not value:
                    raise ValueError(f"{block.where}: not-run needs a reason")
                block.not_run = value
            elif name in _NAVIO2:
                block.not_run = _NAVIO2[name]
            elif name == "docs-test":
                block.options = _options(value, block.where)
        blocks.append(block)
        i = end + 1
    return blocks


def pages() -> list[str]:
    """The docs' pages, and the README (its commands are shown first of all)."""
    return [*sorted(p.name for p in DOCS.glob("*.md")), "../README.md"]


def _read(page: str) -> list[Block]:
    return parse(page, (DOCS / page).read_text(encoding="utf-8"))


# -- the files a page may use without making them -------------------------------------------
def _given(directory: Path) -> None:
    """Put :data:`GIVEN`'s files into ``directory``."""
    for name, make in GIVEN.items():
        make(directory / name)


GIVEN = {
    # a Geofabrik extract as the data page downloads it (a network download: not run here);
    # Malta's of 2018, beside the checkout in ../shared
    "malta-latest.osm.pbf": lambda p: p.symlink_to(MALTA),
    # a national ED-269 geozone download and an OpenAir airspace file (the kit's own samples)
    "zones.json": lambda p: shutil.copy(ROOT / "tests/data/ed269/uaszonelist.json", p),
    "airspace.openair": lambda p: shutil.copy(ROOT / "tests/data/openair/sample.openair", p),
    # the repository's example missions, as the routes page names them from a checkout
    "missions": lambda p: shutil.copytree(ROOT / "missions", p),
    # the live-sources page: the kit's ED-318 sample and the page's own pygeoapi.yml
    "malta-closures.geojson": lambda p: shutil.copy(
        ROOT / "tests/data/ed318/malta-closures.geojson", p
    ),
    "pygeoapi.yml": lambda p: p.write_text(_yaml_block("live-sources.md")),
}


def _yaml_block(page: str) -> str:
    """The first ``yaml`` block of ``page``: a file the page shows whole."""
    return next(b.text for b in _read(page) if b.lang == "yaml")


def _unprivileged(argv: list, directory: Path) -> list:
    """``argv`` as the ``postgres`` user when running as root (PostgreSQL refuses root), with
    ``directory`` open to it."""
    if os.geteuid() != 0:
        return argv
    directory.chmod(0o777)
    for parent in directory.parents:
        if parent == Path(parent.anchor):
            break
        parent.chmod(parent.stat().st_mode | 0o001)
    return ["runuser", "-u", "postgres", "--", *argv]


# -- running a page ---------------------------------------------------------------------------
def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("ALPHAFENCE_")}
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    if (PYGEOAPI / "pygeoapi").exists():  # make test's pygeoapi (the live-sources page)
        env["PATH"] += f"{os.pathsep}{PYGEOAPI}"
    env["COLUMNS"] = "120"
    return env


class Background:
    """A command that runs until Ctrl-C (SITL, the monitor), its output read by a thread."""

    def __init__(self, command: str, cwd: Path, ready: str | None, where: str):
        self.where, self.command = where, command
        self.proc = subprocess.Popen(
            ["bash", "-c", f"exec {command}"],
            cwd=cwd,
            env=_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
            # Ctrl-C must reach it even when the tests run in a background job (whose shell
            # ignores SIGINT, and children inherit that)
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        self.lines: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        while ready is not None:
            try:
                line = self.lines.get(timeout=READY_TIMEOUT_S)
            except queue.Empty:
                self.stop()
                pytest.fail(f"{where}: no {ready!r} within {READY_TIMEOUT_S} s: {command}")
            if line is None:
                pytest.fail(f"{where}: exited before printing {ready!r}: {command}\n{self.text}")
            if ready in line:
                return

    def _read(self):
        for line in self.proc.stdout:
            self.seen.append(line)
            self.lines.put(line)
        self.lines.put(None)

    @property
    def text(self) -> str:
        return "".join(self.seen[-40:])

    def stop(self) -> int:
        """Ctrl-C, as the reader is told to press it; the exit status."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
        try:
            return self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
            return -9


def run_page(page: str, directory: Path, have_sitl: bool) -> list[str]:
    """Run every block of ``page`` in ``directory``; the reasons blocks were left out."""
    _given(directory)
    left_out, background, jobs = [], [], []
    try:
        for block in _read(page):
            if block.lang not in RUN or block.not_run:
                continue
            if block.options.get("sitl") and not have_sitl:
                left_out.append(f"{block.where}: needs SITL")
                continue
            needs = block.options.get("needs")
            if needs and shutil.which(needs, path=_env()["PATH"]) is None:
                left_out.append(f"{block.where}: needs {needs}")
                continue
            expected = int(block.options.get("exit", 0))
            timeout = float(block.options.get("timeout", COMMAND_TIMEOUT_S))
            commands = block.commands()
            for n, command in enumerate(commands, 1):
                status = expected if n == len(commands) else 0
                if command.rstrip().endswith("&"):  # a shell's job: `wait` waits for it
                    jobs.append(Background(command.rstrip()[:-1], directory, None, block.where))
                    continue
                if command.strip() == "wait":
                    for job in jobs:
                        code = job.proc.wait(timeout=timeout)
                        assert code == 0, f"{job.where}: exit {code}: {job.command}\n{job.text}"
                    jobs.clear()
                    continue
                if "background" in block.options:
                    background.append(
                        Background(command, directory, block.options["background"], block.where)
                    )
                    continue
                argv = (
                    [sys.executable, "-c", command]
                    if block.lang == "python"
                    else ["bash", "-c", command]
                )
                if block.options.get("unprivileged"):
                    argv = _unprivileged(argv, directory)
                done = subprocess.run(
                    argv,
                    cwd=directory,
                    env=_env(),
                    capture_output=True,
                    text=True,
                    timeout=timeout,
                )
                assert done.returncode == status, (
                    f"{block.where}: exit {done.returncode}, not {status}: {command}\n"
                    f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
                )
            for job in background:
                assert job.proc.poll() is None, f"{job.where}: stopped early:\n{job.text}"
    finally:
        codes = [(job, job.stop()) for job in reversed(background + jobs)]
        _stop_databases(directory)
    assert not jobs, f"{jobs[0].where}: started with & and never waited for: {jobs[0].command}"
    for job, code in codes:
        assert code in (0, 130), f"{job.where}: exit {code} after Ctrl-C: {job.command}\n{job.text}"
    return left_out


def _stop_databases(directory: Path) -> None:
    """A PostgreSQL cluster a page started and did not stop (it failed first): stopped at
    once (SIGQUIT, its immediate shutdown), so that the next run finds its port free."""
    for pid_file in directory.glob("*/postmaster.pid"):
        try:
            os.kill(int(pid_file.read_text().split()[0]), signal.SIGQUIT)
        except (OSError, ValueError, IndexError):
            pass


def _params():
    out = []
    for page in pages():
        blocks = _read(page)
        if not any(b.lang in RUN and not b.not_run for b in blocks):
            continue
        sitl = any(b.options.get("sitl") and not b.not_run for b in blocks)
        out.append(pytest.param(page, marks=[pytest.mark.sitl] if sitl else [], id=page))
    return out


def _ports(page) -> list:
    """The fixed ports a page's run blocks listen on or connect to (``--port 14550``,
    ``udpin://127.0.0.1:14550``, ``0.0.0.0:8765``), in order."""
    text = "\n".join(b.text for b in _read(page) if b.lang in RUN and not b.not_run)
    return sorted({int(p) for p in re.findall(r"(?:--port |:)(\d{4,5})\b", text)})


@contextlib.contextmanager
def _port_lock(port: int):
    """Exclusive use of ``port`` among the test processes (pytest-xdist's workers): a lock
    file, waited on."""
    import fcntl
    import tempfile

    path = Path(tempfile.gettempdir()) / f"alphafence-docs-port-{port}.lock"
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.mark.parametrize("page", _params())
def test_the_pages_commands_run(page, tmp_path):
    if not MALTA.is_file():
        pytest.skip(f"Malta extract not found at {MALTA} (../shared beside the checkout)")
    from alphafence.sitl.find import find_sitl_binary

    with contextlib.ExitStack() as held:  # one page at a time on each port the pages name
        for port in _ports(page):
            held.enter_context(_port_lock(port))
        folder = tmp_path
        if os.geteuid() == 0:  # outside pytest's folders, which a pytest session that a test
            # starts makes private again, shutting the postgres user out of a page's server
            folder = Path(
                held.enter_context(tempfile.TemporaryDirectory(prefix="alphafence-docs-"))
            )
        left_out = run_page(page, folder, find_sitl_binary() is not None)
    if left_out:
        pytest.skip(f"{len(left_out)} block(s) not run: " + "; ".join(left_out))


def test_every_command_block_is_run_or_says_why_not():
    counts = {"run": 0, "not run": 0}
    for page in pages():
        for block in _read(page):
            if block.lang in RUN:
                counts["not run" if block.not_run else "run"] += 1
                assert block.commands(), f"{block.where}: a {block.lang} block with no command"
            else:
                assert not block.options, f"{block.where}: docs-test on a block never run"
                shown = [x for x in block.text.splitlines() if x.startswith("$ ")]
                assert not shown, (
                    f"{block.where}: a command in a ```{block.lang} block is never run; "
                    "use ```console (or mark it <!-- not-run: REASON -->)"
                )
    assert counts["run"] >= 30, counts  # the pages show their tasks as commands
    print(f"docs command blocks: {counts}")


def test_blocks_and_markers_are_read_as_documented():
    text = (
        "<!-- not-run: downloads from Geofabrik -->\n```console\n$ curl -O URL\n```\n\n"
        "<!-- docs-test: exit=2 sitl -->\n\n```console\n$ alphafence a \\\n    --b c\nout\n"
        "$ alphafence d\n```\n"
        "```sh\n# comment\nx \\\n  y\n\nz\n```\n"
        "<!-- navio2-install: trixie -->\n```sh\nsudo apt update\n```\n"
        "```text\nalphafence: error: x\n```\n"
    )
    a, b, c, d, e = parse("x.md", text)
    assert a.not_run == "downloads from Geofabrik" and a.commands() == ["curl -O URL"]
    assert b.options == {"exit": "2", "sitl": True} and b.line == 8
    assert b.commands() == ["alphafence a \\\n    --b c", "alphafence d"]
    assert c.commands() == ["x \\\n  y", "z"] and not c.not_run
    assert d.not_run and e.lang == "text"
    with pytest.raises(ValueError, match="not-run needs a reason"):
        parse("x.md", "<!-- not-run -->\n```console\n$ x\n```\n")
    with pytest.raises(ValueError, match="not understood"):
        parse("x.md", "<!-- docs-test: exits=2 -->\n```console\n$ x\n```\n")
    with pytest.raises(ValueError, match="never closed"):
        parse("x.md", "```console\n$ x\n")


def test_a_failing_command_fails_its_page(tmp_path, monkeypatch):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "bad.md").write_text("```console\n$ alphafence no-such-verb\n```\n")
    monkeypatch.setattr(sys.modules[__name__], "DOCS", tmp_path / "docs")
    monkeypatch.setattr(sys.modules[__name__], "GIVEN", {})
    work = tmp_path / "work"
    work.mkdir()
    with pytest.raises(AssertionError, match=r"bad.md line 1: exit 2, not 0"):
        run_page("bad.md", work, have_sitl=False)
