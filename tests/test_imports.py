"""What the package imports, and what a base install without the extras can do.

Each check runs in a fresh interpreter and reads ``sys.modules`` (the start-up time itself is a
bench row: ``python -m bench --only cli``). With an import hook that makes pyosmium, scipy,
matplotlib and MAVSDK missing, the verbs that need none of them work and the others say in one
line what to install.
"""

import json
import subprocess
import sys

import pytest

from alphafence.cli import VERBS, main
from alphafence.cli.demo import scene_path

# what the command line's parser must not load: the extras, and the geometry stack that takes
# most of a second to import (alphafence --help stays well under 0.3 s without it)
EXTRAS = ("osmium", "scipy", "matplotlib", "mavsdk", "pymavlink", "grpc")
GEOMETRY = ("numpy", "shapely", "pyproj")

# a meta path finder that refuses the packages named in argv[1] (as if not installed), then
# the command line with argv[2:]; it prints the exit status and what was imported
BLOCKED_RUN = """
import json, sys
blocked = set(filter(None, sys.argv[1].split(",")))

class Missing:
    def find_spec(self, name, path=None, target=None):
        if name in blocked or name.split(".")[0] in blocked:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)

sys.meta_path.insert(0, Missing())
from alphafence.cli import main
try:
    code = main(sys.argv[2:])
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""

NO_EXTRAS = "osmium,scipy,matplotlib,mavsdk"


def _run(argv, blocked=""):
    out = subprocess.run(
        [sys.executable, "-c", BLOCKED_RUN, blocked, *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["code"], set(result["modules"]), out.stderr


def _loaded(modules, names):
    return sorted(n for n in names if n in modules)


def test_importing_the_package_loads_no_dependency():
    code = "import sys, alphafence; print(sorted(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert not _loaded(set(eval(out.stdout)), EXTRAS + GEOMETRY + ("rich",))


def test_help_loads_neither_the_extras_nor_the_geometry():
    code, modules, _ = _run(["--help"])
    assert code == 0
    assert not _loaded(modules, EXTRAS + GEOMETRY)


@pytest.mark.parametrize("verb", VERBS)
def test_each_verbs_help_loads_neither_the_extras_nor_the_geometry(verb):
    code, modules, _ = _run([verb, "--help"])
    assert code == 0
    assert not _loaded(modules, EXTRAS + GEOMETRY)


@pytest.mark.parametrize("verb", VERBS)
def test_importing_a_verb_loads_no_extra(verb):
    module = f"alphafence.cli.{verb.replace('-', '_')}"
    code = f"import sys, {module}; print(sorted(sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert not _loaded(set(eval(out.stdout)), EXTRAS + GEOMETRY)


@pytest.fixture(scope="module")
def fences(tmp_path_factory):
    """The demo scene's fences, built with everything installed."""
    path = tmp_path_factory.mktemp("fences") / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(path), "-q"]) == 0
    return path


# a corner of the demo scene whose fences fit a copter without merging
CORNER = ["--bbox", "-0.57,51.425,-0.56,51.43", "--distance", "300"]
MONITOR = ["monitor", "--connect", "udpin://127.0.0.1:9", "--fences", "{f}", "--allow-unsigned"]


def test_compile_and_check_mission_need_no_extra(fences, tmp_path):
    plan = tmp_path / "onboard.plan"
    code, modules, err = _run(["compile", str(fences), *CORNER, "-o", str(plan)], NO_EXTRAS)
    assert code == 0, err
    items = json.loads(plan.read_text())["geoFence"]
    assert items["polygons"] or items["circles"]
    assert not _loaded(modules, EXTRAS)
    # a mission along the fences: check-mission reads it and the fences, no route planner
    mission = tmp_path / "mission.plan"
    route = ["route", str(fences), "--from", "51.42,-0.56", "--to", "51.44,-0.53"]
    assert main([*route, "-o", str(mission)]) == 0
    code, modules, err = _run(["check-mission", str(mission), "--fences", str(fences)], NO_EXTRAS)
    assert code == 0, err
    assert not _loaded(modules, EXTRAS)


def _one_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_build_of_osm_without_pyosmium_says_what_to_install(tmp_path):
    pbf = tmp_path / "malta.osm.pbf"
    pbf.write_bytes(b"")
    code, _, err = _run(["build", str(pbf), "-o", str(tmp_path / "f.geojson")], NO_EXTRAS)
    assert code == 2
    line = _one_line(err)
    assert line.startswith(f"alphafence build: error: reading {pbf} needs pyosmium 4.0 or later")
    assert "building fences needs scipy" in line
    assert "in the AlphaFence checkout: pip install '.[build]'" in line
    assert "pip install -e '.[all]'" in line and "alphafence[" not in line
    assert "apt install python3-pyosmium python3-scipy" in line


def test_a_pyosmium_without_osmium_filter_is_too_old(tmp_path):
    pbf = tmp_path / "malta.osm.pbf"
    pbf.write_bytes(b"")
    code, _, err = _run(["build", str(pbf), "-o", str(tmp_path / "f.geojson")], "osmium.filter")
    assert code == 2
    assert "is installed, without osmium.filter" in _one_line(err)


@pytest.mark.parametrize(
    "argv, said",
    [
        (["compile", "{f}", *CORNER, "-o", "{t}/o.plan", "--figure", "{t}/o.png"], "drawing"),
        (["compile", "{f}", "--bbox", "-0.58,51.41,-0.52,51.45", "-o", "{t}/o.plan"], "merging"),
        (
            ["route", "{f}", "--from", "51.42,-0.56", "--to", "51.44,-0.53", "-o", "{t}/r.plan"],
            "routing",
        ),  # fmt: skip
        ([*MONITOR, "--imminent-action", "reroute"], "--imminent-action reroute"),
        (
            [*MONITOR, "--onboard", "rolling"],
            "--onboard rolling",
        ),  # fmt: skip
        (["demo", "-o", "{t}/demo"], "building the demo's fences"),
    ],
)
def test_what_needs_an_extra_says_so_in_one_line(fences, tmp_path, argv, said):
    argv = [a.format(f=fences, t=tmp_path) for a in argv]
    code, modules, err = _run(argv, NO_EXTRAS)
    assert code == 2
    line = _one_line(err)
    assert said in line and "pip install '.[build]'" in line, line
    assert not (tmp_path / "o.plan").exists()  # nothing half-written


def test_signing_setup_without_pymavlink_names_the_companion_extra(tmp_path):
    argv = ["signing", "setup", "--connect", "udpin://127.0.0.1:9", "--key", str(tmp_path / "k")]
    code, _, err = _run(argv, NO_EXTRAS + ",pymavlink")
    assert code == 2
    line = _one_line(err)
    assert (
        "signing setup needs pymavlink: in the AlphaFence checkout: pip install '.[companion]'"
        in line
    )


def _free_udp_port():
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("verb", ["monitor", "download"])
def test_the_companion_verbs_run_on_pymavlink_alone(fences, tmp_path, verb):
    # no vehicle answers: the verb gets as far as its link (exit 3), with no extra but pymavlink
    url = f"udpin://127.0.0.1:{_free_udp_port()}"
    argv = {
        "monitor": ["monitor", "--fences", str(fences), "--allow-unsigned"],
        "download": ["download", "-o", str(tmp_path / "d.plan")],
    }[verb]
    code, modules, err = _run([*argv, "--connect", url, "--timeout", "1"], NO_EXTRAS)
    assert code == 3, err
    assert "no autopilot answered" in err
    assert "pymavlink" in modules
    assert not _loaded(modules, ("osmium", "scipy", "matplotlib", "mavsdk"))


def test_a_build_of_malta_loads_no_other_verb_nor_what_it_does_not_use(malta, tmp_path):
    """A whole build of Malta (alpha fences, no figure or map): no other verb's module, no
    vehicle link or event loop, no matplotlib; and none of scipy's modules (only its package,
    checked for as the build needs it), as Malta's regions are small enough to group without
    scipy.sparse and its sites' fences need no triangulation."""
    code, modules, err = _run(["build", str(malta), "-o", str(tmp_path / "f.geojson"), "-q"])
    assert code == 0, err
    others = [f"alphafence.cli.{v.replace('-', '_')}" for v in VERBS if v != "build"]
    assert _loaded(modules, others) == []
    assert _loaded(modules, ["asyncio", "matplotlib", "pymavlink", "alphafence.vehicle"]) == []
    assert _loaded(modules, ["scipy.sparse", "scipy.spatial", "scipy.linalg"]) == []
    assert (tmp_path / "f.geojson").stat().st_size > 0
