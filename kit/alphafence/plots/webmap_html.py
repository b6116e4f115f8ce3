"""One self-contained HTML map page: Leaflet (its CSS and JS), the kit's map script and the
data, all inlined, so the file opens with no network. Nothing is fetched unless the user gives
a tile URL template for a basemap.

The page's data is JSON in ``<script type="application/json" id="af-data">``; every ``<`` in
it is written as ``\\u003c``, so no text in the data (a fence's name, say) can close the tag
or open a comment.
"""

from __future__ import annotations

import json
import re
from functools import cache
from html import escape
from importlib import resources

#: The kit's own scripts inlined by default (in ``alphafence/data/web``).
SCRIPTS = ("alphafence-map.js",)

# Leaflet's stylesheet names a few images beside it (the layer control's icon, the default
# marker); the page has no files beside it, so they are drawn without (the kit's script uses
# no default marker, and its own CSS draws the layer control's icon).
_CSS_URL = re.compile(r"url\(images/[^)]*\)")
_CSS_COMMENT = re.compile(r"/\*.*?\*/", re.S)

_STYLE = """
html, body, #map { height: 100%; margin: 0; }
body { font: 13px/1.35 system-ui, sans-serif; }
.leaflet-container { background: #f5f5f2; }
.leaflet-control-layers-toggle { background-image: none; }
.leaflet-control-layers-toggle::after { content: "\\2630"; font-size: 20px; line-height: 36px;
  display: block; text-align: center; color: #333; }
.af-legend { background: #fff; padding: 6px 8px; border-radius: 4px; max-width: 260px;
  box-shadow: 0 1px 5px rgba(0,0,0,.4); }
.af-legend .af-row { display: flex; align-items: center; gap: 6px; margin: 2px 0; }
.af-legend .af-swatch { width: 18px; height: 10px; flex: none; border: 2px solid; }
.af-legend .af-ramp { height: 8px; width: 120px; }
.af-title { font-weight: 600; margin-bottom: 3px; }
.af-note { color: #555; font-size: 11px; margin-top: 4px; }
.af-grid-label { color: #444; font-size: 10px; white-space: nowrap; text-shadow: 0 0 2px #fff; }
.af-popup td { padding: 1px 6px 1px 0; vertical-align: top; }
.af-popup td:first-child { color: #555; }
"""


@cache
def _asset(*parts) -> str:
    return resources.files("alphafence").joinpath("data", "web", *parts).read_text("utf-8")


def leaflet_css() -> str:
    """Leaflet's stylesheet, as inlined: its comments dropped and its image URLs removed
    (the page fetches nothing).

    Examples
    --------
    >>> css = leaflet_css()
    >>> ".leaflet-container" in css, "url(images/" in css, "http" in css
    (True, False, False)
    """
    return _CSS_COMMENT.sub("", _CSS_URL.sub("none", _asset("leaflet", "leaflet.css")))


def data_json(data) -> str:
    """``data`` as JSON that is safe inside a ``<script>`` element: every ``<`` escaped.

    Examples
    --------
    >>> data_json({"name": "</script><b>x"})
    '{"name":"\\\\u003c/script>\\\\u003cb>x"}'
    >>> json.loads(data_json({"name": "</script>"}))["name"]
    '</script>'
    """
    text = json.dumps(data, ensure_ascii=False, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c")


def _inline_script(text: str) -> str:
    # a script's text ends at the first "</script"; the bundled scripts never hold one
    if re.search(r"</script", text, re.I):
        raise ValueError("a script to inline holds '</script'")
    return f"<script>\n{text}\n</script>"


def page(title, data, script_names=SCRIPTS, *, tiles=None, extra_js="") -> str:
    """A self-contained HTML map page.

    Parameters
    ----------
    title : str
        The page's title (escaped).
    data : dict
        What the kit's map script draws (``layers``, ``note``...), inlined as JSON.
    script_names : sequence of str
        The kit's scripts (in ``alphafence/data/web``) to inline after Leaflet, in order.
    tiles : dict, optional
        A basemap: ``{"url": "https://.../{z}/{x}/{y}.png", "attribution": "..."}`` (the
        only thing the page then fetches), or ``{"data": {"z/x/y": "data:image/png;base64,..."},
        "attribution": ...}`` for tiles held in the page. None: no basemap, no request.
    extra_js : str
        A script run after the others (e.g. a live feed's client).

    Returns
    -------
    str
        The HTML document.

    Examples
    --------
    >>> html = page("Fences <Malta>", {"layers": [], "name": "</script>"})
    >>> html.startswith("<!DOCTYPE html>"), "<title>Fences &lt;Malta&gt;</title>" in html
    (True, True)
    >>> html.count("</script>") == html.count("<script")
    True
    >>> 'id="af-data"' in html and "window.afMap" in html
    True
    """
    data = dict(data)
    if tiles:
        data["tiles"] = tiles
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{escape(str(title))}</title>",
        f"<style>\n{leaflet_css()}\n{_STYLE}</style>",
        "</head>",
        "<body>",
        '<div id="map"></div>',
        f'<script type="application/json" id="af-data">{data_json(data)}</script>',
        _inline_script(_asset("leaflet", "leaflet.js")),
    ]
    parts += [_inline_script(_asset(name)) for name in script_names]
    if extra_js:
        parts.append(_inline_script(extra_js))
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)
