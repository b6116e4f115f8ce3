"""Interactive HTML maps: the layers of a map page (fences by kind, restricted areas, onboard
items) as GeoJSON for the kit's map script, and the page written all or nothing.

The page (:mod:`alphafence.plots.webmap_html`) holds Leaflet and the data, so it opens with
no network. Coordinates are rounded to 1e-6 degrees (about 0.1 m) to keep a country's fences
small; Leaflet draws them on one canvas, simplified for the zoom.
"""

from __future__ import annotations

import json

import numpy as np
import shapely

from alphafence.fencefiles.atomic import write_all
from alphafence.plots.webmap_html import page

DIGITS = 6  # 1e-6 degrees: about 0.1 m

#: The fence kinds' layers: name, colour, stroke and fill, as the PNG figures draw them
#: (:data:`alphafence.plots.common.KIND_STYLE`).
KIND_LAYERS = {
    "warning": dict(name="warning layers", color="#ef8f00", dash="6 4", weight=1.2,
                    legend="warning layer"),
    "keep_in": dict(name="keep-in fences", color="#2e7d32", weight=1.8, legend="keep-in fence"),
    "keep_out": dict(name="keep-out fences", color="#c62828", fill=0.13, weight=1.4,
                     legend="keep-out fence"),
}  # fmt: skip
RESTRICTED = dict(name="restricted areas", color="#616161", fill=0.45, weight=0.6,
                  legend="restricted area (the data)")  # fmt: skip
INCLUSION_COLOR, EXCLUSION_COLOR, RETURN_COLOR = "#2e7d32", "#c62828", "#1565c0"
NOT_IN_FORCE_COLOR = "#9e9e9e"
#: Line colour per fence method (:data:`alphafence.plots.common.METHOD_COLOR`).
METHOD_COLORS = {"alpha": "#1565c0", "polygon": "#6a1b9a", "circle": "#ef6c00", "exact": "#2e7d32"}


def rounded_geojson(geoms) -> list:
    """GeoJSON geometries (dicts) of shapely geometries, coordinates rounded to
    :data:`DIGITS` decimals of a degree.

    Examples
    --------
    >>> rounded_geojson([shapely.Point(14.123456789, 35.9)])
    [{'type': 'Point', 'coordinates': [14.123457, 35.9]}]
    """
    arr = np.empty(len(geoms), dtype=object)
    arr[:] = list(geoms)
    arr = shapely.transform(arr, lambda c: np.round(c, DIGITS))
    return [json.loads(text) for text in shapely.to_geojson(arr).tolist()]


def feature(geometry: dict, title=None, popup=(), **props) -> dict:
    """A GeoJSON Feature for the map script: its ``title`` and ``popup`` rows
    (``[label, value]``) shown on a click, and drawing hints (``color``, ``radius_m``).

    Examples
    --------
    >>> feature({"type": "Point", "coordinates": [1, 2]}, "home", [("alt", "0 m")])["properties"]
    {'title': 'home', 'popup': [['alt', '0 m']]}
    """
    props = {k: v for k, v in props.items() if v is not None}
    if title is not None:
        props["title"] = str(title)
    props["popup"] = [[str(k), str(v)] for k, v in popup]
    return {"type": "Feature", "geometry": geometry, "properties": props}


def band_text(lo, hi, lower_ref=None, upper_ref=None) -> str:
    """A fence's altitude band with its references.

    Examples
    --------
    >>> band_text(None, None)
    'all altitudes'
    >>> band_text(0, 120.5, "AGL", "AMSL")
    '0 m AGL to 120.5 m AMSL'
    >>> band_text(None, 150)
    'up to 150 m (above home)'
    """
    if lo is None and hi is None:
        return "all altitudes"
    low = None if lo is None else f"{lo:g} m {lower_ref or '(above home)'}"
    high = None if hi is None else f"{hi:g} m {upper_ref or '(above home)'}"
    if low is None:
        return f"up to {high}"
    return f"{low} and up" if high is None else f"{low} to {high}"


def fence_popup(p: dict) -> list:
    """The rows shown on a click on a fence, from its GeoJSON properties: name, category,
    kind, band with references, margin, vertices, area and sources."""
    zone = p.get("zone") or {}
    sources = p.get("sources") or []
    shown = ", ".join(map(str, sources[:6])) + (f" and {len(sources) - 6} more" if len(sources) > 6 else "")  # fmt: skip
    rows = [
        ("name", p.get("name") or "(none)"),
        ("site", p.get("site_id", "")),
        ("category", p.get("category") or "-"),
        ("kind", str(p.get("kind", "")).replace("_", "-")),
        ("band", band_text(p.get("alt_min_m"), p.get("alt_max_m"),
                           zone.get("lower_reference"), zone.get("upper_reference"))),
        ("margin", f"{p.get('margin_m', 0):g} m"),
        ("vertices", p.get("vertices", "-")),
        ("area", f"{p['area_m2']:,.0f} m²" if p.get("area_m2") is not None else "-"),
        ("sources", shown or "-"),
    ]  # fmt: skip
    if p.get("method"):
        rows.append(("method", p["method"]))
    if zone.get("restriction"):
        rows.append(("restriction", zone["restriction"]))
    return rows


def _properties(fence) -> dict:
    props = getattr(fence, "properties", None)
    if isinstance(props, dict) and "kind" in props:  # a FenceRecord read back
        return props
    if hasattr(fence, "sources"):  # a built Fence
        from alphafence.fencefiles.fence_geojson import fence_properties

        return fence_properties(fence)
    return {"site_id": fence.site_id, "kind": fence.kind, "name": fence.name,
            "category": fence.category, "margin_m": fence.margin_m,
            "alt_min_m": fence.alt_min_m, "alt_max_m": fence.alt_max_m}  # fmt: skip


def fence_layers(fences, in_force=None, names=None) -> list:
    """One layer per fence kind (warning layers first, keep-out fences on top).

    Parameters
    ----------
    fences : sequence of FenceRecord or Fence
        Read back (``read_fences``) or built; their geometries in lon/lat.
    in_force : dict, optional
        Fence index -> ``"yes"``, ``"no"`` or ``"partly"``: fences never in force are grey.
    names : dict, optional
        Layer name per kind, replacing :data:`KIND_LAYERS`' names.

    Returns
    -------
    list of dict
        Layer specs for :func:`write_map`; kinds without a fence are left out.
    """
    fences = list(fences)
    geoms = rounded_geojson([f.geometry for f in fences])
    by_kind = {k: [] for k in KIND_LAYERS}
    for k, (f, g) in enumerate(zip(fences, geoms)):
        p = _properties(f)
        rows = fence_popup(p)
        color = None
        if in_force is not None and k in in_force:
            rows.append(("in force during the flight", in_force[k]))
            color = NOT_IN_FORCE_COLOR if in_force[k] == "no" else None
        title = p.get("name") or p.get("site_id")
        by_kind.setdefault(f.kind, []).append(feature(g, title, rows, color=color))
    layers = []
    for kind, spec in KIND_LAYERS.items():
        if by_kind.get(kind):
            name = (names or {}).get(kind, spec["name"])
            layers.append({**spec, "name": name, "features": by_kind[kind]})
    return layers


def method_layers(by_method) -> list:
    """One layer per fence method, in the method's colour, for ``compare``.

    Parameters
    ----------
    by_method : dict
        ``{method: {site_id: Fence}}`` (``Comparison.fences``).
    """
    layers = []
    for m, fences in by_method.items():
        feats = [f for lay in fence_layers(list(fences.values())) for f in lay["features"]]
        color = METHOD_COLORS.get(m, "#333333")
        for f in feats:
            f["properties"]["color"] = color
        layers.append({"name": f"{m} fences", "color": color, "fill": 0.06, "weight": 1.5,
                       "legend": f"{m} fence", "features": feats})  # fmt: skip
    return layers


def restricted_layer(sites) -> dict:
    """The restricted areas (the data the fences were built of) of built sites, in grey."""
    geoms = [s.frame.geom_to_wgs84(s.geometry) for s in sites]
    feats = [
        feature(g, s.name or s.site_id, [("site", s.site_id), ("category", s.category)])
        for s, g in zip(sites, rounded_geojson(geoms))
    ]
    return {**RESTRICTED, "features": feats}


def onboard_layers(fences, return_point=None, name="onboard items", exclusion=None) -> list:
    """The fence items as the vehicle holds them: polygons and circles (inclusion green,
    exclusion red), each named as the monitor names it, and the return point.

    Parameters
    ----------
    fences : list of OnboardFence
        As :func:`alphafence.onboard.decode.decode_fence` reads the items.
    return_point : tuple, optional
        ``(lon, lat)``.
    name : str
        The layer's name.
    exclusion : str, optional
        The exclusions' colour (default red; blue over full-resolution fences).
    """
    excl = exclusion or EXCLUSION_COLOR
    feats = []
    for f in sorted(fences, key=lambda f: f.inclusion):
        rows = [("kind", f.kind), ("shape", f.shape), ("items", f.items)]
        color = INCLUSION_COLOR if f.inclusion else excl
        if f.shape == "circle":
            (lon, lat), r = f.lonlat[0], f.radius_m
            geom = {"type": "Point", "coordinates": [round(lon, DIGITS), round(lat, DIGITS)]}
            rows.append(("radius", f"{r:g} m"))
            feats.append(feature(geom, f.name, rows, color=color, radius_m=r))
            continue
        ring = [[round(x, DIGITS), round(y, DIGITS)] for x, y in f.lonlat]
        geom = {"type": "Polygon", "coordinates": [ring + ring[:1]]}
        rows.append(("vertices", len(f.lonlat)))
        feats.append(feature(geom, f.name, rows, color=color))
    layers = []
    if feats:
        layers.append({"name": name, "color": excl, "fill": 0.1, "weight": 1.6,
                       "legend_rows": [[f"onboard {k}", c] for k, c in
                                       (("inclusion", INCLUSION_COLOR), ("exclusion", excl))
                                       if any(f.kind == k for f in fences)],
                       "features": feats})  # fmt: skip
    if return_point is not None:
        lon, lat = return_point
        geom = {"type": "Point", "coordinates": [round(lon, DIGITS), round(lat, DIGITS)]}
        rows = [("position", f"{lat:.6f}, {lon:.6f} (lat, lon)")]
        layers.append({"name": "return point", "color": RETURN_COLOR, "radius": 8,
                       "legend": "return point",
                       "features": [feature(geom, "fence return point", rows)]})  # fmt: skip
    return layers


def bounds_of(lonlat) -> list:
    """``[[south, west], [north, east]]`` of ``(lon, lat)`` rows, for the page to fit."""
    xy = np.asarray(lonlat, float).reshape(-1, 2)
    return [[float(xy[:, 1].min()), float(xy[:, 0].min())],
            [float(xy[:, 1].max()), float(xy[:, 0].max())]]  # fmt: skip


def write_map(path, title, layers, note=None, tiles=None, bounds=None, legend_note=None):
    """Write the map page to ``path`` (all or nothing).

    Parameters
    ----------
    path : str or Path
        The HTML file.
    title : str
        The page's title, also at the top of the legend.
    layers : list of dict
        Layer specs (:func:`fence_layers`, :func:`onboard_layers`...), drawn in order (the
        last on top); empty ones are not listed.
    note : str, optional
        Small print in the corner (the data's attribution).
    tiles : dict, optional
        A basemap (see :func:`alphafence.plots.webmap_html.page`).
    bounds : list, optional
        ``[[south, west], [north, east]]`` to show first; default: every layer.
    legend_note : str, optional
        A line under the legend.
    """
    data = {"title": title, "layers": [lay for lay in layers if lay.get("features")]}
    for key, value in (("note", note), ("bounds", bounds), ("legend_note", legend_note)):
        if value:
            data[key] = value
    write_all({path: page(title, data, tiles=tiles)})
