"""Tables name fences by their site: ``compile`` rows by site id and name, a compiled plan
records which sites each polygon and circle stands for, and ``upload --dry-run`` of that plan
shows them beside each item row."""

import io
import json

import pytest
import shapely

from alphafence.cli import main
from alphafence.cli.demo import scene_path
from alphafence.fencefiles.fence_geojson import read_fences
from alphafence.fencefiles.qgc_plan import read_plan_geofence

BOX = "--bbox=-0.58,51.42,-0.52,51.44"


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    """The demo scene's fences, compiled into a plan, and what compile printed."""
    from alphafence.cli import common

    d = tmp_path_factory.mktemp("names")
    fences = d / "fences.geojson"
    assert main(["build", str(scene_path()), "-o", str(fences), "-q"]) == 0
    plan = d / "onboard.plan"
    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(common.out_console, "_file", buf)
        mp.setattr(common.out_console, "_width", 400)
        assert main(["compile", str(fences), BOX, "-o", str(plan)]) == 0
    return fences, plan, buf.getvalue()


def entry_shape(entry):
    if "polygon" in entry:
        return shapely.Polygon([(lon, lat) for lat, lon in entry["polygon"]])
    lat, lon = entry["circle"]["center"]
    return shapely.Point(lon, lat).buffer(entry["circle"]["radius"] / 111_000 * 2)


def test_compile_names_each_row_by_its_sites(compiled):
    fences, _, printed = compiled
    named = [r for r in read_fences(fences) if r.name and r.kind == "keep_out"]
    assert named
    for r in named:
        assert f"{r.site_id} ({r.name})" in printed, r.site_id


def test_each_plan_fence_records_the_sites_it_stands_for(compiled):
    fences, plan, _ = compiled
    records = {r.site_id: r for r in read_fences(fences) if r.kind == "keep_out"}
    doc = json.loads(plan.read_text())
    entries = doc["geoFence"]["polygons"] + doc["geoFence"]["circles"]
    read = read_plan_geofence(plan).sites
    assert len(read) == len(entries) and all(read)
    for entry, sites in zip(entries, read):
        assert entry["alphafence"]["sites"] == sites
        shape = entry_shape(entry)
        for site in sites:
            record = records[site["id"]]
            assert site["name"] == record.name
            # the onboard keep-out fence stands for this site: it holds (covers) it
            assert shape.buffer(1e-6).covers(record.geometry), site["id"]
    stood_for = {s["id"] for sites in read for s in sites}
    assert stood_for and stood_for <= set(records)


def test_upload_dry_run_shows_each_items_site(compiled, capsys):
    fences, plan, _ = compiled
    from alphafence.cli import common

    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(common.out_console, "_file", buf)
        mp.setattr(common.out_console, "_width", 400)
        assert main(["upload", str(plan), "--dry-run", "--allow-unsigned"]) == 0
    rows = [line for line in buf.getvalue().splitlines() if "exclusion " in line]
    sites = read_plan_geofence(plan).sites
    assert len(rows) == len(sites)
    for row, stands_for in zip(rows, sites):
        for site in stands_for:
            assert f"{site['id']} ({site['name']})" in row, row


def test_a_plan_without_our_key_or_with_a_foreign_one_names_no_site(compiled, tmp_path):
    _, plan, _ = compiled
    doc = json.loads(plan.read_text())
    doc["geoFence"]["polygons"][0]["alphafence"] = "not ours"
    doc["geoFence"]["polygons"][1].pop("alphafence")
    other = tmp_path / "other.plan"
    other.write_text(json.dumps(doc))
    sites = read_plan_geofence(other).sites
    assert sites[0] == [] and sites[1] == [] and sites[2]
