"""Coverage-guided fuzzing with atheris (libFuzzer for Python), next to the hypothesis fuzz tests.

hypothesis generates structured inputs (documents that are almost right); atheris mutates raw
bytes guided by which lines of the kit they reach, so it finds what a structure-aware generator
does not think of. Every reader, and the signed MAVLink link's parser, must answer any byte
string with a clean one-line InputError (readers) or by dropping it (the link); any other
exception is a crash that libFuzzer reports with the input that caused it (written to
crash-*).

    make fuzz-atheris                      # every target, ATHERIS_RUNS inputs each
    .venv/bin/python tests/atheris_fuzz.py geojson -runs=100000 -max_len=4096

Seeds are the kit's own files (the demo scene, the rules), so mutation starts from valid input.
Not part of `make test`: atheris is an optional install (``pip install -e '.[fuzz]'``).
"""

from __future__ import annotations

import os
import sys
import tempfile
from importlib import resources
from pathlib import Path

import atheris

with atheris.instrument_imports(include=["alphafence"]):
    from alphafence.errors import InputError
    from alphafence.fencefiles.fence_geojson import read_fences
    from alphafence.fencefiles.qgc_plan import read_plan_fence
    from alphafence.fencefiles.qgc_wpl import read_waypoints_fence
    from alphafence.vehicle.bridge import VehicleLink
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

RULES = load_rules()
KEY = bytes(range(32))


def _reader(fn, suffix):
    def target(data: bytes) -> None:
        fd, name = tempfile.mkstemp(suffix=suffix)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        try:
            fn(Path(name))
        except InputError as exc:
            text = str(exc)
            if not text or "\n" in text:
                raise AssertionError(f"not a one-line error: {text!r}") from None
        finally:
            os.unlink(name)

    return target


def _mavlink(data: bytes) -> None:
    got = []
    link = VehicleLink("udpout://127.0.0.1:9", KEY, got.append)
    link._received(data, ("127.0.0.1", 1))
    if got and link.stats.received != len(got):
        raise AssertionError("messages delivered without being counted")


TARGETS = {
    "geojson": _reader(lambda p: read_database([p], RULES), ".geojson"),
    "ed269": _reader(lambda p: read_database([p], RULES), ".json"),
    "osm": _reader(lambda p: read_database([p], RULES), ".osm"),
    "fences": _reader(read_fences, ".geojson"),
    "plan": _reader(read_plan_fence, ".plan"),
    "waypoints": _reader(read_waypoints_fence, ".waypoints"),
    "rules": _reader(load_rules, ".toml"),
    "mavlink": _mavlink,
}


def seeds(target: str) -> list[bytes]:
    data = resources.files("alphafence") / "data"
    if target == "ed269":  # both ED-269 wrappers and ED-318, as others write them
        return [p.read_bytes() for p in sorted((Path(__file__).parent / "data/ed269").glob("*"))]
    if target in ("geojson", "fences"):
        return [(data / "demo-scene.geojson").read_bytes()[:4096]]
    if target == "rules":
        return [(data / "rules.toml").read_bytes()]
    if target == "waypoints":
        return [b"QGC WPL 110\n0\t1\t0\t5001\t4\t0\t0\t0\t35.9\t14.5\t0\t1\n"]
    if target == "plan":
        return [b'{"fileType": "Plan", "geoFence": {"polygons": [], "circles": [], "version": 2}}']
    if target == "osm":
        return [b'<osm version="0.6"><node id="1" lat="35.9" lon="14.5"/></osm>']
    return [bytes.fromhex("fd0900000101010000000000000000000203510403")]


def main(argv: list[str]) -> None:
    if len(argv) < 2 or argv[1] not in TARGETS:
        sys.exit(f"usage: atheris_fuzz.py {{{','.join(TARGETS)}}} [libFuzzer options]")
    target = argv[1]
    corpus = Path(tempfile.mkdtemp(prefix=f"atheris-{target}-"))
    for i, seed in enumerate(seeds(target)):
        (corpus / f"seed{i}").write_bytes(seed)
    atheris.Setup([argv[0], *argv[2:], str(corpus)], TARGETS[target])
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
