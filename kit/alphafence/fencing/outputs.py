"""Render a build's outputs (GeoJSON, .plan, .waypoints) as text, for an all-or-nothing write."""

from __future__ import annotations

from alphafence import __version__
from alphafence.fencefiles import fence_geojson as geojson
from alphafence.fencefiles import qgc_plan as plan
from alphafence.fencefiles import qgc_wpl as waypoints
from alphafence.mavlink.items import fence_items

OSM_ATTRIBUTION = "Contains data © OpenStreetMap contributors, ODbL 1.0"


def build_meta(db, rules, options) -> dict:
    """What a build was made of, for the fence GeoJSON's ``"alphafence"`` member: tool, inputs,
    rules, method and its options, the bbox, OSM's attribution when OSM data was read, the
    zones left out as no area (``skipped_invalid``: file, airspace, line, problem) and what was
    read other than as written (``notes``) when there are any."""
    meta = {
        "tool": f"alphafence {__version__}",
        "inputs": db.files,
        "rules": rules.source,
        "method": options.method,
        "join_m": options.join_m,
        "warn_distance_m": options.warn_distance_m,
        "max_vertices": options.max_vertices,
    }
    if options.alpha_radius is not None:
        meta["alpha_radius_m"] = options.alpha_radius
    if options.margin_m is not None:
        meta["margin_override_m"] = options.margin_m
    if getattr(options, "max_overshoot_m", None) is not None:
        meta["max_overshoot_m"] = options.max_overshoot_m
    if db.bbox:
        meta["bbox"] = list(db.bbox)
    if any(".osm" in f or f.endswith(".pbf") for f in db.files):
        meta["attribution"] = OSM_ATTRIBUTION
    if getattr(db, "invalid", None):
        meta["skipped_invalid"] = list(db.invalid)
    if getattr(db, "notes", None):
        meta["notes"] = list(db.notes)
    return meta


def render(fences, meta, geojson_path=None, plan_path=None, waypoints_path=None) -> dict:
    """A build's outputs as text, ready for an all-or-nothing ``write_all``.

    Parameters
    ----------
    fences : list of Fence
    meta : dict
        From :func:`build_meta`.
    geojson_path, plan_path, waypoints_path : str or Path, optional
        The outputs wanted: the fence GeoJSON, a QGroundControl plan and a QGC WPL fence
        file (the last two hold keep-out and keep-in fences only).

    Returns
    -------
    dict
        ``{path: text}``.
    """
    out = {}
    if geojson_path:
        out[geojson_path] = geojson.dumps(geojson.fences_geojson(fences, meta))
    items = fence_items(fences) if (plan_path or waypoints_path) else []
    if plan_path:
        out[plan_path] = plan.dumps(plan.plan_document(items))
    if waypoints_path:
        out[waypoints_path] = waypoints.waypoints_text(items)
    return out
