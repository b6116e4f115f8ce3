"""``make mutation``: break the safety-critical code on purpose, one small change at a time
(mutmut 3), and see that a test notices each break.

Each target of ``tests/mutation/targets.toml`` is run in a workspace of its own (mutmut wants
the package under ``src/``: the workspace holds a copy of ``kit/alphafence`` there, and of the
tests). A mutant no test kills is a *survivor*: the run fails on any survivor not listed in
``tests/mutation/survivors.toml`` with the reason it is harmless (equivalent to the code, or
a change no reading of the fence can see), and says how to list or kill it. A listed survivor
that a test now kills is reported, to take off the list.

Usage::

    python -m tests.mutation                  # every target
    python -m tests.mutation --target "lazy check"
    python -m tests.mutation --changed        # the targets whose module differs from the
                                              # one scores.json was recorded on
    python -m tests.mutation --record         # write scores.json (scores, module hashes)

Under CI (``.ci/run``) ``--changed --canary "fast decoder and signing"`` runs the targets a change
touched, or the canary alone when none was, within ``--budget`` seconds.
"""

from __future__ import annotations

import argparse
import datetime
import fnmatch
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
KIT = ROOT / "kit"
MUTMUT = Path(sys.executable).parent / "mutmut"


def targets() -> list[dict]:
    return tomllib.loads((HERE / "targets.toml").read_text())["target"]


def survivors_listed() -> list[dict]:
    return tomllib.loads((HERE / "survivors.toml").read_text()).get("survivor", [])


def module_hash(module: str) -> str:
    return hashlib.sha256((KIT / module).read_bytes()).hexdigest()[:16]


def dotted(module: str) -> str:
    return module.removesuffix(".py").replace("/", ".")


def workspace(target: dict, base: Path) -> Path:
    """A folder holding ``src/alphafence`` (the kit), the tests and a pyproject whose
    ``[tool.mutmut]`` mutates the target's module and runs its tests."""
    work = base / re.sub(r"\W+", "-", target["name"])
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".hypothesis")
    shutil.copytree(KIT / "alphafence", work / "src" / "alphafence", ignore=ignore)
    shutil.copytree(ROOT / "tests", work / "tests", ignore=ignore)
    pyproject = (ROOT / "pyproject.toml").read_text().replace('where = ["kit"]', 'where = ["src"]')
    options = ["-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:randomly"]
    pyproject += (
        "\n[tool.mutmut]\n"
        'source_paths = ["src/alphafence"]\n'
        f'only_mutate = ["src/{target["module"]}"]\n'
        f"pytest_add_cli_args_test_selection = {json.dumps(target['tests'])}\n"
        f"pytest_add_cli_args = {json.dumps(options)}\n"
        'also_copy = ["tests", "pyproject.toml"]\n'
    )
    (work / "pyproject.toml").write_text(pyproject)
    return work


def _mutmut(work: Path, *args, timeout=None) -> subprocess.CompletedProcess:
    env = dict(os.environ, CI="true", PYTHONDONTWRITEBYTECODE="1")
    env["ALPHAFENCE_SHARED"] = env.get("ALPHAFENCE_SHARED", str(ROOT.parent / "shared"))
    return subprocess.run([str(MUTMUT), *args], cwd=work, env=env, text=True,
                          capture_output=True, timeout=timeout)  # fmt: skip


def _wanted(name: str, target: dict) -> bool:
    """Whether mutant ``name`` (``alphafence.mod.x_func__mutmut_3``) is of a target's
    functions."""
    function = name.removeprefix(dotted(target["module"]) + ".").rsplit("__mutmut_", 1)[0]
    return any(fnmatch.fnmatchcase(function, f) for f in target["functions"])


def mutant_change(work: Path, name: str) -> tuple[str, str, str]:
    """``(function, removed, added)``: what a mutant changes, as lines stripped of spaces
    (how survivors.toml names it, stable when other code moves)."""
    diff = _mutmut(work, "show", name).stdout.splitlines()
    removed = " | ".join(
        x[1:].strip() for x in diff if x.startswith("-") and not x.startswith("---")
    )
    added = " | ".join(x[1:].strip() for x in diff if x.startswith("+") and not x.startswith("+++"))
    function = name.split(".")[-1].rsplit("__mutmut_", 1)[0]
    return function, removed, added


def run_target(target: dict, base: Path, budget_s: float | None) -> dict:
    """Mutate one target and return its counts and survivors."""
    work = workspace(target, base)
    started = time.monotonic()
    names = [f"{dotted(target['module'])}.{f}*" for f in target["functions"]]
    try:
        done = _mutmut(work, "run", *names, timeout=budget_s)
    except subprocess.TimeoutExpired:
        raise SystemExit(f"{target['name']}: not done within {budget_s:g} s") from None
    if done.returncode != 0:
        raise SystemExit(f"mutmut failed on {target['name']}:\n{done.stdout[-3000:]}{done.stderr}")
    results = _mutmut(work, "results", "--all", "true").stdout
    status = {}
    for line in results.splitlines():
        found = re.match(r"\s*(\S+): (.+)$", line)
        if found and _wanted(found.group(1), target):
            status[found.group(1)] = found.group(2).strip()
    alive = sorted(n for n, s in status.items() if s in ("survived", "no tests"))
    killed = sum(s in ("killed", "timeout", "segfault") for s in status.values())
    changes = [(n, *mutant_change(work, n)) for n in alive]
    return {
        "name": target["name"],
        "module": target["module"],
        "mutants": len(status),
        "killed": killed,
        "survivors": changes,
        "seconds": round(time.monotonic() - started),
        "other": sorted({s for s in status.values()} - {"killed", "survived", "no tests",
                                                        "timeout", "segfault"}),
    }  # fmt: skip


def _key(module, function, removed, added):
    return module, function, " ".join(removed.split()), " ".join(added.split())


def judge(result: dict, listed: list[dict]) -> tuple[list, list]:
    """The survivors not listed, and the listed ones of this module that no longer survive."""
    known = {_key(s["module"], s["function"], s["removed"], s["added"]): s for s in listed}
    seen, unlisted = set(), []
    for name, function, removed, added in result["survivors"]:
        key = _key(result["module"], function, removed, added)
        if key in known:
            seen.add(key)
        else:
            unlisted.append((name, function, removed, added))
    stale = [s for k, s in known.items() if k[0] == result["module"] and k not in seen]
    return unlisted, stale


def changed_targets(all_targets: list[dict]) -> list[dict]:
    path = HERE / "scores.json"
    recorded = json.loads(path.read_text())["modules"] if path.exists() else {}
    return [t for t in all_targets if recorded.get(t["module"]) != module_hash(t["module"])]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tests.mutation", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--target", action="append", help="a target's name (repeatable)")
    ap.add_argument("--changed", action="store_true",
                    help="only the targets whose module changed since scores.json")  # fmt: skip
    ap.add_argument("--canary", help="with --changed: the target run when none changed")
    ap.add_argument("--budget", type=float, help="seconds each target may take")
    ap.add_argument("--record", action="store_true", help="write tests/mutation/scores.json")
    ap.add_argument("--stanzas", help="append survivors.toml stanzas of unlisted survivors here")
    args = ap.parse_args(argv)
    if not MUTMUT.exists():
        print(f"mutmut is not installed beside {sys.executable} (pip install 'mutmut>=3.3')")
        return 2
    chosen = targets()
    if args.target:
        chosen = [t for t in chosen if t["name"] in args.target]
    if args.changed:
        chosen = changed_targets(chosen) or [t for t in targets() if t["name"] == args.canary]
    listed = survivors_listed()
    base = Path(tempfile.mkdtemp(prefix="alphafence-mutation-"))
    failed, rows = False, []
    try:
        for target in chosen:
            print(f"mutating {target['module']} ({target['name']})...", flush=True)
            result = run_target(target, base, args.budget)
            unlisted, stale = judge(result, listed)
            rows.append(result)
            score = result["killed"] / result["mutants"] if result["mutants"] else 1.0
            print(f"  {result['killed']}/{result['mutants']} killed ({score:.1%}), "
                  f"{len(result['survivors'])} survived ({len(unlisted)} unlisted), "
                  f"{result['seconds']} s")  # fmt: skip
            for name, function, removed, added in unlisted:
                failed = True
                print(f"  UNLISTED SURVIVOR {name}\n    in {function}: {removed!r} -> {added!r}")
                if args.stanzas:
                    with open(args.stanzas, "a", encoding="utf-8") as fh:
                        fh.write(stanza(result["module"], function, removed, added))
            for s in stale:
                print(f"  listed, but killed now: {s['function']}: {s['added']!r} (take it off)")
    finally:
        shutil.rmtree(base, ignore_errors=True)
    if failed:
        print("a survivor is a break no test noticed: kill it with a test, or list it in "
              "tests/mutation/survivors.toml with why it is harmless")  # fmt: skip
    if args.record and not failed:
        record(rows)
    return 1 if failed else 0


def stanza(module, function, removed, added) -> str:
    """A survivors.toml entry for a survivor, its reason left to write."""
    q = json.dumps  # a TOML basic string is a JSON string
    return (f"\n[[survivor]]\nmodule = {q(module)}\nfunction = {q(function)}\n"
            f"removed = {q(removed)}\nadded = {q(added)}\nwhy = \"\"\n")  # fmt: skip


def record(rows: list[dict]) -> None:
    path = HERE / "scores.json"
    doc = json.loads(path.read_text()) if path.exists() else {"modules": {}, "scores": {}}
    today = datetime.date.today().isoformat()
    for r in rows:
        doc["modules"][r["module"]] = module_hash(r["module"])
        doc["scores"][r["name"]] = {"module": r["module"], "mutants": r["mutants"],
                                    "killed": r["killed"], "survived": len(r["survivors"]),
                                    "seconds": r["seconds"], "date": today}  # fmt: skip
    path.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
    print(f"recorded {path.relative_to(ROOT)}")


if __name__ == "__main__":
    sys.exit(main())
