"""The package's shape: stages import only the stages below them, no module imports itself
back through others, every MAVLink number matches MAVLink's own definition, and every public
class and function says what it does."""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import alphafence

PACKAGE = Path(alphafence.__file__).parent

# the stages, bottom up: a module may import its own stage and any stage ranked below it
RANK = {
    "errors": 0,
    "geo": 1,
    "mavlink": 2,
    "zones": 3,
    "fencefiles": 4,
    "sources": 4,
    "fencing": 5,
    "flights": 5,
    "onboard": 6,
    "updating": 6,
    "route": 6,
    "awareness": 6,
    "vehicle": 7,
    "sitl": 8,
    "monitor": 9,
    "plots": 9,
    "review": 10,
    "livemap": 10,
    "cli": 11,
    "__main__": 12,
}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield ".".join(["alphafence", *parts]), path


def _imports(path, name):
    """Every alphafence module ``path`` imports, at any depth of the code."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "alphafence")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "alphafence":
                continue
            for a in node.names:  # `from alphafence.fencefiles import qgc_plan` imports a module
                sub = f"{mod}.{a.name}"
                out.add(sub if sub in MODULES else mod)
    return {m for m in out if m != name}


MODULES = dict(_modules())
GRAPH = {name: _imports(path, name) for name, path in MODULES.items()}


def _stage(module):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_every_module_is_in_a_known_stage():
    unknown = {m for m in MODULES if _stage(m) is not None and _stage(m) not in RANK}
    assert not unknown, f"add these to RANK (and to the README's layout): {sorted(unknown)}"


def test_no_module_imports_a_stage_above_its_own():
    upward = []
    for module, imported in GRAPH.items():
        stage = _stage(module)
        for other in imported:
            if other == "alphafence":  # the root holds only __version__ and lazy exports
                continue
            if _stage(other) != stage and RANK[_stage(other)] >= RANK[stage]:
                upward.append(f"{module} -> {other}")
    assert not upward, "imports against the flow:\n" + "\n".join(sorted(upward))


def test_the_import_graph_has_no_cycle():
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(GRAPH.get(m, ())):
            if n not in GRAPH:
                continue
            if state.get(n) == 1:
                cycles.append(" -> ".join(stack[stack.index(n) :] + [n]))
            elif n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(GRAPH):
        if m not in state:
            visit(m)
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_importing_the_package_loads_no_stage():
    import subprocess
    import sys

    code = (
        "import sys, alphafence; "
        "print(sorted(m for m in sys.modules if m.startswith('alphafence.')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert alphafence.read_database.__module__ == "alphafence.zones.database"


def test_no_room_holds_more_than_20_modules_or_15_percent_of_the_lines():
    """A room that grows past this is a storeroom: split it by what flows through it."""
    modules, lines = {}, {}
    for name, path in MODULES.items():
        n = len(path.read_text().splitlines())
        stage = _stage(name) if path.parent != PACKAGE else None
        if stage is not None and path.name != "__init__.py":
            modules[stage] = modules.get(stage, 0) + 1
            lines[stage] = lines.get(stage, 0) + n
    total = sum(len(p.read_text().splitlines()) for p in MODULES.values())
    big = {s: (modules[s], round(100 * lines[s] / total, 1)) for s in modules
           if modules[s] > 20 or lines[s] > 0.15 * total}  # fmt: skip
    assert not big, f"rooms over 20 modules or 15 % of the package's lines: {big}"
    assert len(modules) >= 12  # the rooms are there to count


def test_no_module_is_over_400_lines():
    long = {m: n for m, p in MODULES.items() if (n := len(p.read_text().splitlines())) > 400}
    assert not long, f"split these by what they hold: {long}"


def _public_definitions():
    for info in pkgutil.walk_packages([str(PACKAGE)], prefix="alphafence."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != info.name:
                continue
            if inspect.isclass(obj) or inspect.isfunction(obj):
                yield f"{info.name}.{name}", obj
                if inspect.isclass(obj):
                    for attr, member in vars(obj).items():
                        if attr.startswith("_") or not inspect.isfunction(member):
                            continue
                        yield f"{info.name}.{name}.{attr}", member


@pytest.mark.filterwarnings("ignore")
def test_every_public_class_and_function_has_a_docstring():
    missing = sorted(name for name, obj in _public_definitions() if not inspect.getdoc(obj))
    assert not missing, f"{len(missing)} without a docstring:\n" + "\n".join(missing)


def test_the_readme_layout_is_the_real_tree():
    readme = (PACKAGE.parents[1] / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = readme.split("## Layout", 1)[1].split("```", 2)[1]
    listed, folder = set(), None
    for line in block.splitlines()[1:]:
        if not line.strip() or line.startswith("kit/"):
            continue
        indent = len(line) - len(line.lstrip())
        words = line.split()
        if indent == 2 and words[0].endswith("/"):
            folder = words[0]
            continue
        names = (
            [w for w in words if w.endswith(".py")]
            if indent == 4 or words[0].endswith(".py")
            else []
        )
        names = names if indent == 4 else names[:1]
        prefix = folder if indent == 4 else ""
        listed.update(prefix + n for n in names)
    real = {
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if p.name != "__main__.py" and (p.name != "__init__.py" or p.parent == PACKAGE)
    }
    assert listed == real, (
        f"in the README, not in the tree: {sorted(listed - real)}; "
        f"in the tree, not in the README: {sorted(real - listed)}"
    )
