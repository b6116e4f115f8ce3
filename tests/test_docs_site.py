"""The docs site builds with `mkdocs build --strict` and no warning: every page in the nav,
every link and anchor found (mkdocs.yml's validation turns each into a warning)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs", reason="mkdocs not installed (pip install '.[docs]')")

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _build(config: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},  # Material's notice of its successor
    )


def test_the_site_builds_strictly_without_a_warning(tmp_path):
    done = _build(ROOT / "mkdocs.yml", tmp_path / "site")
    log = done.stdout + done.stderr
    warnings = [line for line in log.splitlines() if re.match(r"\s*(WARNING|ERROR)\b", line)]
    assert done.returncode == 0 and not warnings, log
    pages = {p.stem for p in DOCS.glob("*.md")}
    built = {p.parent.name for p in (tmp_path / "site").glob("*/index.html")}
    assert pages - {"index"} <= built


def test_a_broken_anchor_fails_the_build(tmp_path):
    # the same configuration over a copy of the docs with one link to a missing heading
    docs = tmp_path / "docs"
    docs.mkdir()
    for page in DOCS.iterdir():
        (docs / page.name).write_bytes(page.read_bytes())
    index = docs / "index.md"
    index.write_text(index.read_text() + "\n[gone](build.md#no-such-heading)\n")
    config = (ROOT / "mkdocs.yml").read_text()
    (tmp_path / "mkdocs.yml").write_text(config)
    done = _build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0
    assert "no-such-heading" in done.stdout + done.stderr


def test_no_page_reads_as_a_work_diary():
    words = re.compile(r"\b(session|sessions|issue \d+|this VM)\b", re.I)
    found = [
        f"{page.name}:{n}: {line.strip()}"
        for page in [*DOCS.glob("*.md"), ROOT / "CONTRIBUTING.md"]
        for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
        if words.search(line)
    ]
    assert not found, "\n".join(found)
