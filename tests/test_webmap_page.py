"""The HTML map page: one self-contained file whose data cannot break out of its script tag,
and that names no web address but a basemap's tile template when one is given."""

from __future__ import annotations

import json
import re

from hypothesis import given
from hypothesis import strategies as st

from alphafence.formats.webmap_html import page

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
