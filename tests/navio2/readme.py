"""The README's Navio2 install blocks and the systemd unit, read for run.sh and the tests.

A README code block preceded by ``<!-- navio2-install: SUITE [SUITE...] -->`` is what a Navio2
user types on that Debian suite (trixie, bookworm); run.sh runs those blocks, in order, in the
armhf userland, so that the README and the test cannot drift.

Command line (run.sh uses it)::

    python -m tests.navio2.readme blocks trixie     # the blocks' text, one after the other
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "docs" / "navio2.md"  # the Navio2 install steps
UNIT = ROOT / "docker" / "alphafence-monitor.service"

_MARKER = re.compile(r"^<!--\s*navio2-install:\s*([a-z0-9 ]+?)\s*-->\s*$")


def install_blocks(text: str, suite: str) -> list[str]:
    """The code blocks of ``text`` marked for ``suite``, in order, each as its text.

    Raises ValueError when a marker is not followed by a fenced code block.
    """
    lines = text.splitlines()
    blocks = []
    for i, line in enumerate(lines):
        m = _MARKER.match(line.strip())
        if not m or suite not in m.group(1).split():
            continue
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        if j >= len(lines) or not lines[j].startswith("```"):
            raise ValueError(f"README line {i + 1}: navio2-install marker without a code block")
        end = next((k for k in range(j + 1, len(lines)) if lines[k].startswith("```")), None)
        if end is None:
            raise ValueError(f"README line {j + 1}: code block never closed")
        blocks.append("\n".join(lines[j + 1 : end]) + "\n")
    return blocks


def unit_settings(text: str) -> dict:
    """The systemd unit's ``[Service]`` settings: ``User``, ``ExecStart`` and the others as
    strings, ``Environment`` as a dict (uncommented lines only)."""
    settings: dict = {"Environment": {}}
    section = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith(("#", ";")):
            continue
        if line.startswith("["):
            section = line.strip("[]")
            continue
        if section != "Service" or "=" not in line:
            continue
        key, value = line.split("=", 1)
        if key == "Environment":
            name, val = value.split("=", 1)
            settings["Environment"][name] = val
        else:
            settings[key] = value
    return settings


def main(argv: list[str]) -> int:
    """``blocks SUITE``: print the suite's install blocks (exit 1 if there are none)."""
    if len(argv) != 2 or argv[0] != "blocks":
        print("usage: python -m tests.navio2.readme blocks SUITE", file=sys.stderr)
        return 2
    blocks = install_blocks(README.read_text(encoding="utf-8"), argv[1])
    if not blocks:
        print(f"README.md has no navio2-install block for {argv[1]}", file=sys.stderr)
        return 1
    sys.stdout.write("\n".join(blocks))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
