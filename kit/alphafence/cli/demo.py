"""alphafence demo: the main job on the shipped synthetic demo scene."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from alphafence.build.compare import compare_methods, telling_sites
from alphafence.build.fences import METHODS
from alphafence.build.outputs import build_meta, render
from alphafence.build.pipeline import BuildOptions, build_fences
from alphafence.cli.common import out_console
from alphafence.cli.tables import stats_table
from alphafence.formats.atomic import write_all
from alphafence.formats.database import read_database
from alphafence.formats.rules import load_rules
from alphafence.plots.compare import comparison_figure
from alphafence.plots.fences import fence_map

NOTE = "Synthetic demo scene authored by the AlphaFence project (not real places)."


def scene_path() -> Path:
    """The shipped synthetic demo scene (GeoJSON)."""
    return Path(str(resources.files("alphafence").joinpath("data/demo-scene.geojson")))


def register(sub):
    """Add the ``demo`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "demo",
        help="build fences for the shipped synthetic demo scene",
        description="Run the main job on the synthetic demo scene and compare the methods.",
    )
    p.add_argument(
        "-o",
        "--output-dir",
        default="demo-out",
        metavar="DIR",
        help="where to write (default demo-out)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    """Build, draw and compare fences for the demo scene into ``--output-dir``; exit 0."""
    out = Path(args.output_dir)
    scene = scene_path()
    rules = load_rules()
    db = read_database([scene], rules)
    opts = BuildOptions(method="alpha")
    result = build_fences(db.features, rules, opts)
    meta = build_meta(db, rules, opts)
    meta["note"] = NOTE
    paths = {k: out / f"fences.{k}" for k in ("geojson", "plan", "waypoints")}
    write_all(render(result.fences, meta, paths["geojson"], paths["plan"], paths["waypoints"]))
    fence_map(
        result.fences,
        result.sites,
        out / "fences.png",
        title="AlphaFence demo: alpha fences",
        note=NOTE,
    )
    out_console.print(f"[bold]AlphaFence demo[/] on {scene.name} ({NOTE})")
    out_console.print(
        f"{len(db.features)} restricted features -> {len(result.sites)} sites -> "
        f"{len(result.fences)} fences ({len(db.repaired)} invalid polygon(s) repaired)"
    )
    cmp = compare_methods(db.features, rules, list(METHODS), opts)
    out_console.print(stats_table(cmp, opts))
    comparison_figure(telling_sites(cmp), cmp.fences, out / "compare.png", note=NOTE)
    out_console.print(
        "wrote "
        + ", ".join(str(p) for p in [*paths.values(), out / "fences.png", out / "compare.png"])
    )
    return 0
