"""docker/Dockerfile.armv7 as a shell script, for run.sh's ``docker`` phase.

No Docker engine runs on the machines this project is built on, so `make navio2-test` checks
the armv7 image's steps in a fresh overlay of the same Debian armhf userland instead: every
``RUN`` as written, ``COPY`` from the build context (the kit's source, at ``/context``),
``ENV`` and ``WORKDIR`` as the image has them, and at the end, as the image's ``USER``, the
commands the image's entrypoint relies on. Only the instructions this Dockerfile uses are
understood; any other stops the conversion.

    python -m tests.navio2.dockerfile docker/Dockerfile.armv7 > script.sh
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

CONTEXT = "/context"


def instructions(text: str) -> list[tuple[str, str]]:
    """``(INSTRUCTION, arguments)`` in order, continuation lines joined, comments dropped."""
    out, current = [], ""
    for raw in text.splitlines():
        line = raw.strip()
        if not current and (not line or line.startswith("#")):
            continue
        if line.startswith("#"):
            continue
        current += line[:-1] + " " if line.endswith("\\") else line
        if not line.endswith("\\"):
            word, _, rest = current.partition(" ")
            out.append((word.upper(), " ".join(rest.split())))
            current = ""
    return out


def script(text: str, base: str) -> str:
    """The Dockerfile as a bash script run as root in the userland (``base``: the ``FROM``
    image this userland stands for, e.g. ``debian:trixie-slim``)."""
    lines = ["set -euxo pipefail"]
    user, entrypoint = "root", None
    for word, args in instructions(text):
        if word == "FROM":
            if args != base:
                raise ValueError(f"FROM {args}: this userland stands for {base}")
        elif word == "RUN":
            lines.append(args)
        elif word == "COPY":
            *sources, dest = shlex.split(args)
            if dest.endswith("/"):
                lines.append(f"mkdir -p {shlex.quote(dest)}")
            else:
                lines.append(f"mkdir -p {shlex.quote(str(Path(dest).parent))}")
            srcs = " ".join(shlex.quote(f"{CONTEXT}/{s}") for s in sources)
            lines.append(f"cp -r {srcs} {shlex.quote(dest)}")
        elif word == "ENV":
            lines.append(f"export {args}")
        elif word == "WORKDIR":
            lines.append(f"mkdir -p {shlex.quote(args)} && cd {shlex.quote(args)}")
        elif word == "USER":
            user = args
        elif word == "ENTRYPOINT":
            entrypoint = json.loads(args)[0]
        else:
            raise ValueError(f"{word}: not understood by tests/navio2/dockerfile.py")
    # what the entrypoint runs, as the image's user: its command, the monitor, the link
    check = (
        f"command -v {entrypoint} && alphafence --version && alphafence monitor --help >/dev/null"
        " && python3 -c 'import pymavlink, alphafence.vehicle.link'"
        " && ! python3 -c 'import mavsdk' 2>/dev/null"
    )
    lines.append(f"setpriv --reuid={user} --regid={user} --init-groups sh -c {shlex.quote(check)}")
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    """``DOCKERFILE BASE``: print the script."""
    path, base = argv
    sys.stdout.write(script(Path(path).read_text(encoding="utf-8"), base))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
