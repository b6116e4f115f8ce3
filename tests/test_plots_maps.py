"""Every map the kit draws, read back from the figure it wrote (the commands run on the demo
scene and on Monaco): a scale bar of a round length about a fifth of the map, metres from an
origin the axes name and that every figure of one set of fences shares, the largest sites
named with no name over another, a legend of exactly what is drawn and beside the map, and no
text outside the PNG written."""

import json
import math
import re
import struct
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
import shapely
from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

from alphafence.cli import main
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.qgc_plan import read_plan_fence
from alphafence.geo.frame import LocalFrame
from alphafence.mavlink.items import POLYGON_INCLUSION, RETURN_POINT
from alphafence.plots import common

ORIGIN = re.compile(r"east of (\d+\.\d+)°([NS]) (\d+\.\d+)°([EW]) \(m\)")
KINDS = {"keep-out fence": "keep_out", "warning layer": "warning", "keep-in fence": "keep_in"}


def capture(mp):
    """The figures the commands write, by the PNG's file name (captured as they are closed
    and written)."""
    figs, closed = {}, []
    close, write = plt.close, common.write_bytes_atomic

    def closing(fig=None):
        closed.append(fig)
        close(fig)

    def writing(path, data):
        figs[Path(path).name] = closed[-1]
        write(path, data)

    mp.setattr(plt, "close", closing)
    mp.setattr(common, "write_bytes_atomic", writing)
    return figs


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo (replayed), then upload --dry-run, compile, route and check-flight on what it
    wrote, each with --figure: the folder and the figures."""
    out = tmp_path_factory.mktemp("maps")
    fences = str(out / "fences.geojson")
    with pytest.MonkeyPatch.context() as mp:
        figs = capture(mp)
        assert main(["demo", "-o", str(out), "--replay"]) == 0
        argv = ["upload", str(out / "onboard.plan"), "--dry-run", "--allow-unsigned"]
        assert main([*argv, "--figure", str(out / "items.png")]) == 0
        assert main(["compile", fences, "--bbox=-0.58,51.42,-0.52,51.44", "--items", "40",
                     "--keep-in", "300", "--return-point", "51.43,-0.55", "-o",
                     str(out / "c.plan"), "--figure", str(out / "compile.png")]) == 0  # fmt: skip
        assert main(["route", fences, "--from", "51.4245,-0.5700", "--to", "51.4330,-0.5380",
                     "--clearance", "25", "-o", str(out / "m.plan"),
                     "--figure", str(out / "route.png")]) == 0  # fmt: skip
        argv = ["check-flight", str(out / "flight.tlog"), "--fences", fences]
        assert main([*argv, "--figure", str(out / "check.png")]) == 0
    return out, figs


def renderer(fig):
    """A renderer at the PNG's resolution for a figure already written and closed (closing
    left it no Agg canvas)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig.set_dpi(common.DPI)
    if not hasattr(fig.canvas, "get_renderer"):
        FigureCanvasAgg(fig)
    return fig.canvas.get_renderer()


def the_map(fig):
    """The figure's one map axes (the one with a scale bar)."""
    (ax,) = [ax for ax in fig.axes if scale_bars(ax)]
    return ax


def scale_bars(ax):
    return [a for a in ax.artists if isinstance(a, AnchoredSizeBar)]


def check_scale_bar(ax):
    """One scale bar, labelled with its length, 1, 2 or 5 × 10^n m, a tenth to two fifths of
    the map's width."""
    (bar,) = scale_bars(ax)
    number, unit = re.fullmatch(r"(\d+(?:\.\d+)?) (m|km)", bar.txt_label.get_text()).groups()
    metres = float(number) * (1000 if unit == "km" else 1)
    (rect,) = bar.size_bar.get_children()
    assert rect.get_width() == pytest.approx(metres)
    assert round(metres / 10 ** math.floor(math.log10(metres)), 9) in (1, 2, 5)
    width = abs(float(np.diff(ax.get_xlim())[0]))
    assert 0.1 <= metres / width <= 0.4, (metres, width)


def origin(ax):
    """The origin the axes name, ``(lon, lat)``, and its name."""
    m = ORIGIN.fullmatch(ax.get_xlabel())
    assert m, ax.get_xlabel()
    name = ax.get_xlabel()[len("east of ") : -len(" (m)")]
    assert ax.get_ylabel() == f"north of {name} (m)"
    lat = float(m[1]) * (1 if m[2] == "N" else -1)
    lon = float(m[3]) * (1 if m[4] == "E" else -1)
    return (lon, lat), name


def check_at_origin(ax, geom):
    """A patch of ``ax`` is ``geom`` (WGS84) in metres from the origin its axes name."""
    (lon, lat), _ = origin(ax)
    want = np.asarray(LocalFrame(lon, lat).geom_to_local(geom).bounds)
    got = [np.r_[p.get_path().vertices.min(0), p.get_path().vertices.max(0)] for p in ax.patches]
    assert min(np.abs(g - want).max() for g in got) < 1.0, want


def legend_labels(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def check_legend_beside(ax):
    r = renderer(ax.figure)
    assert not ax.get_legend().get_window_extent(r).overlaps(ax.get_window_extent(r))


def png_size(path):
    w, h = struct.unpack(">II", Path(path).read_bytes()[16:24])
    return w, h


def texts(fig):
    """Every text the figure shows: titles, labels, tick labels in view, annotations, the
    legend's and the scale bars'."""
    out = [*fig.texts, *[t for t in [fig._suptitle] if t is not None]]
    for ax in fig.axes:
        out += [ax.title, ax.xaxis.label, ax.yaxis.label, *ax.texts]
        for axis, (lo, hi) in (
            (ax.xaxis, sorted(ax.get_xlim())),
            (ax.yaxis, sorted(ax.get_ylim())),
        ):
            out += [t.label1 for t in axis.get_major_ticks() if lo <= t.get_loc() <= hi]
        if ax.get_legend():
            out += ax.get_legend().get_texts()
        out += [b.txt_label._text for b in scale_bars(ax)]
    return [t for t in out if t.get_visible() and t.get_text().strip()]


def check_nothing_cut_off(fig, png):
    """The PNG is the figure's saved box, and every text lies inside it."""
    r = renderer(fig)
    saved = fig.get_tightbbox(r).padded(common.PAD_INCHES)
    w, h = png_size(png)
    assert abs(w - saved.width * common.DPI) <= 2 and abs(h - saved.height * common.DPI) <= 2
    shown = texts(fig)
    assert shown
    for t in shown:
        bb = t.get_window_extent(r).transformed(fig.dpi_scale_trans.inverted())
        inside = saved.x0 - 1e-6 <= bb.x0 and bb.x1 <= saved.x1 + 1e-6
        assert inside and saved.y0 - 1e-6 <= bb.y0 and bb.y1 <= saved.y1 + 1e-6, t.get_text()


def site_labels(ax):
    """The site names: the texts drawn with a halo."""
    return [t for t in ax.texts if t.get_path_effects()]


def check_names_apart(ax):
    r = renderer(ax.figure)
    boxes = [t.get_window_extent(r) for t in site_labels(ax)]
    frame = ax.get_window_extent(r)
    for i, b in enumerate(boxes):
        assert frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1
        assert not any(b.overlaps(o) for o in boxes[i + 1 :])


@pytest.mark.parametrize(
    "png", ["fences.png", "flight.png", "items.png", "compile.png", "route.png", "check.png"]
)
def test_each_map_has_a_scale_bar_a_named_origin_a_legend_beside_it_and_nothing_cut_off(demo, png):
    out, figs = demo
    ax = the_map(figs[png])
    check_scale_bar(ax)
    origin(ax)
    check_legend_beside(ax)
    check_names_apart(ax)
    check_nothing_cut_off(figs[png], out / png)


def test_every_map_of_the_demo_fences_names_the_same_origin_and_draws_them_from_it(demo):
    out, figs = demo
    names = {png: origin(the_map(fig))[1] for png, fig in figs.items() if png != "compare.png"}
    assert len(names) == 6 and len(set(names.values())) == 1, names
    records = read_fences(out / "fences.geojson")
    hospital = next(r for r in records if r.kind == "keep_out" and "Hospital" in (r.name or ""))
    for png in ("fences.png", "flight.png", "check.png", "route.png"):
        check_at_origin(the_map(figs[png]), hospital.geometry)
    # the origin: the centre of the fences' bounds, rounded to 0.01°
    (lon, lat), _ = origin(the_map(figs["fences.png"]))
    x0, y0, x1, y1 = shapely.GeometryCollection([r.geometry for r in records]).bounds
    assert abs(lon - (x0 + x1) / 2) <= 0.005 and abs(lat - (y0 + y1) / 2) <= 0.005


def test_legends_list_what_is_drawn(demo, tmp_path, capsys):
    out, figs = demo
    records = read_fences(out / "fences.geojson")
    kinds = {r.kind for r in records}
    for png in ("fences.png", "flight.png"):
        labels = legend_labels(the_map(figs[png]))
        assert len(labels) == len(set(labels))
        assert {KINDS[lab] for lab in labels if lab in KINDS} == kinds, (png, labels)
    assert "restricted area" in legend_labels(the_map(figs["fences.png"]))
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    marked = {e["level"] for e in events if e.get("level") in ("WARNING", "IMMINENT", "BREACH")}
    assert marked and marked <= set(legend_labels(the_map(figs["flight.png"])))
    assert "BREACH" not in legend_labels(the_map(figs["flight.png"]))
    items = read_plan_fence(out / "onboard.plan")
    want = {"exclusion (stay out)"}
    want |= (
        {"inclusion (stay inside)"} if any(i.command == POLYGON_INCLUSION for i in items) else set()
    )
    want |= {"return point"} if any(i.command == RETURN_POINT for i in items) else set()
    assert set(legend_labels(the_map(figs["items.png"]))) == want
    # the same flight checked against fences without warning layers: no warning entry
    doc = json.loads((out / "fences.geojson").read_text())
    doc["features"] = [f for f in doc["features"] if f["properties"]["kind"] != "warning"]
    bare = tmp_path / "bare.geojson"
    bare.write_text(json.dumps(doc))
    with pytest.MonkeyPatch.context() as mp:
        mine = capture(mp)
        argv = ["check-flight", str(out / "flight.tlog"), "--fences", str(bare)]
        assert main([*argv, "--figure", str(tmp_path / "bare.png")]) == 0
    ax = the_map(mine["bare.png"])
    assert "warning layer" not in legend_labels(ax)
    assert "warning layer" in legend_labels(the_map(figs["check.png"]))
    assert "keep-out fence" in legend_labels(ax)
    check_legend_beside(ax)


def test_the_comparison_has_a_scale_bar_in_every_panel_and_names_each_rows_centre(demo):
    out, figs = demo
    fig = figs["compare.png"]
    assert len(fig.axes) >= 4
    for ax in fig.axes:
        check_scale_bar(ax)
    rows = [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel()]
    assert rows and all(re.search(r"centred on \d+\.\d{4}°[NS] \d+\.\d{4}°[EW]$", r) for r in rows)
    check_nothing_cut_off(fig, out / "compare.png")


def test_monacos_largest_sites_are_named(monaco, tmp_path):
    out = tmp_path / "monaco.geojson"
    with pytest.MonkeyPatch.context() as mp:
        figs = capture(mp)
        argv = ["build", str(monaco), "-o", str(out), "--figure", str(tmp_path / "m.png")]
        assert main([*argv, "--quiet"]) == 0
    ax = the_map(figs["m.png"])
    records = read_fences(out)
    frame = LocalFrame.around(shapely.GeometryCollection([r.geometry for r in records]))
    by_name = {}
    for r in records:
        by_name.setdefault(r.name or r.site_id, []).append(frame.geom_to_local(r.geometry))
    assert len({r.site_id for r in records}) == 27
    largest = sorted(by_name, key=lambda n: -shapely.union_all(by_name[n]).area)
    named = [t.get_text() for t in site_labels(ax)]
    assert 8 <= len(named) <= 10, named
    short = [n if len(n) <= 32 else n[:31] + "…" for n in largest]
    assert named[0] == short[0] and set(named) <= set(short[:15]), (named, short[:15])
    check_names_apart(ax)
    check_scale_bar(ax)
    check_legend_beside(ax)
    check_nothing_cut_off(figs["m.png"], tmp_path / "m.png")
