"""The HTML map page: one self-contained file whose data cannot break out of its script tag,
and that names no web address but a basemap's tile template when one is given."""

from __future__ import annotations

import json
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from alphafence.plots.webmap_html import page

URL = re.compile(r"https?://[^\s\"'<>)]+")
# what Leaflet's own source holds: its licence comment and attribution prefix name its site
# (the kit's script replaces the prefix), and the SVG namespace (a name, never fetched)
LEAFLET_OWN = {"https://leafletjs.com", "http://www.w3.org/2000/svg"}


def _data_of(html):
    m = re.search(r'<script type="application/json" id="af-data">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


def _fence(name):
    ring = [[14.5, 35.9], [14.51, 35.9], [14.51, 35.91], [14.5, 35.9]]
    return {
        "type": "Feature",
        "geometry": {"type": "Polygon", "coordinates": [ring]},
        "properties": {"title": name, "popup": [["name", name]]},
    }


@given(st.text(max_size=40), st.text(max_size=40))
def test_any_text_in_the_data_stays_data(name, title):
    data = {"title": title, "layers": [{"name": name, "features": [_fence(name)]}]}
    html = page(title, data)
    assert _data_of(html) == data
    # the data element holds no '<' at all, so nothing in it can end it or open a comment
    block = html.split('id="af-data">', 1)[1].split("</script>", 1)[0]
    assert "<" not in block
    assert html.count("<script") == html.count("</script>")


@given(st.text(alphabet=st.characters(exclude_characters=":"), max_size=30))
def test_the_page_names_no_web_address_but_the_tile_template(name):
    data = {"title": name, "layers": [{"name": name, "features": [_fence(name)]}]}
    assert set(URL.findall(page("fences", data))) <= LEAFLET_OWN
    template = "https://tiles.example.org/{z}/{x}/{y}.png"
    tiled = page("fences", data, tiles={"url": template, "attribution": "© example"})
    assert set(URL.findall(tiled)) == LEAFLET_OWN | {template}


def test_leaflet_and_the_kit_script_are_inlined():
    html = page("fences", {"layers": []})
    assert "Leaflet 1.9.4" in html and "window.afLayers" in html
    assert ".leaflet-container" in html
    assert not re.search(r"<(script|link|img)[^>]+(src|href)=", html)


def test_the_maps_colours_are_the_figures_colours():
    from alphafence.plots.common import KIND_STYLE, METHOD_COLOR
    from alphafence.plots.webmap import KIND_LAYERS, METHOD_COLORS

    assert {k: v["color"] for k, v in KIND_LAYERS.items()} == {
        k: v["edgecolor"] for k, v in KIND_STYLE.items()
    }
    assert METHOD_COLORS == METHOD_COLOR


def _mbtiles(path, tiles, fmt="png"):
    import sqlite3

    db = sqlite3.connect(path)
    db.execute("CREATE TABLE metadata (name text, value text)")
    db.execute(
        "CREATE TABLE tiles (zoom_level integer, tile_column integer, tile_row integer, "
        "tile_data blob)"
    )
    db.executemany(
        "INSERT INTO metadata VALUES (?, ?)", [("format", fmt), ("attribution", "© sample")]
    )
    db.executemany("INSERT INTO tiles VALUES (?, ?, ?, ?)", tiles)
    db.commit()
    db.close()
    return path


def test_an_mbtiles_basemap_holds_the_tiles_around_the_data(tmp_path):
    from alphafence.errors import InputError
    from alphafence.plots.mbtiles import tile_range, tiles_around

    bounds = [[35.88, 14.40], [35.92, 14.52]]
    z = 12
    x0, x1, y0, y1 = tile_range(bounds, z)
    png = b"\x89PNG\r\n\x1a\n" + b"\0" * 100
    inside = [(z, x, 2**z - 1 - y, png) for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)]
    far = [(z, x1 + 5, 2**z - 1 - y0, png)]  # a tile away from the data
    path = _mbtiles(tmp_path / "base.mbtiles", inside + far)
    held, attribution = tiles_around(path, bounds)
    want = {f"{z}/{x}/{y}" for x in range(x0, x1 + 1) for y in range(y0, y1 + 1)}
    assert set(held) == want and attribution == "© sample"
    assert all(v.startswith("data:image/png;base64,") for v in held.values())
    with pytest.raises(InputError, match="more than"):
        tiles_around(path, bounds, max_bytes=len(png) * (len(want) - 1))
