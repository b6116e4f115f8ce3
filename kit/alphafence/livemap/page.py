"""The live map's page: the kit's HTML map shell (:mod:`alphafence.plots.webmap_html`:
Leaflet and the map script inlined, nothing fetched) with the live script
(``alphafence/data/web/alphafence-live.js``), which draws what the server pushes."""

from __future__ import annotations

from alphafence.plots.webmap_html import SCRIPTS, page

LIVE_SCRIPT = "alphafence-live.js"
STYLE_NOTE = "live: the vehicle, its predicted path, the fences near it and its own fence"


def live_page(title: str = "AlphaFence live map") -> str:
    """The live map's HTML page (no data of its own: everything comes over the WebSocket).

    Examples
    --------
    >>> html = live_page()
    >>> "window.afLive" in html and "new WebSocket" in html
    True
    """
    return page(title, {"layers": [], "note": STYLE_NOTE}, (*SCRIPTS, LIVE_SCRIPT))
