"""The layers of the interactive maps that are not fences: a compile's corridor, a route over its roadmap, a mission's legs by what ``check-mission`` found, and a
logged flight's track coloured by altitude with its breaches and alerts."""

from __future__ import annotations

import numpy as np
import shapely

from alphafence.plots.webmap import DIGITS, feature, rounded_geojson

#: Leg colours by ``check-mission``'s verdict.
LEG_COLORS = {
    "crosses a keep-out fence": "#c62828",
    "leaves a keep-in fence": "#ad1457",
    "grazes a fence": "#ef8f00",
    "clear": "#2e7d32",
}
#: The flight track's altitude ramp, low to high (viridis).
RAMP = ("#440154", "#3b528b", "#21918c", "#5ec962", "#fde725")
EVENT_COLOR, BREACH_COLOR, ROUTE_COLOR = "#6a1b9a", "#c62828", "#1565c0"
ROADMAP_COLOR, CORRIDOR_COLOR, PATH_COLOR = "#9e9e9e", "#757575", "#212121"


def _line(lonlat) -> dict:
    pts = np.round(np.asarray(lonlat, float).reshape(-1, 2), DIGITS)
    return {"type": "LineString", "coordinates": pts.tolist()}


def _point(lon, lat) -> dict:
    return {"type": "Point", "coordinates": [round(float(lon), DIGITS), round(float(lat), DIGITS)]}


def corridor_layers(corridor, frame) -> list:
    """A compile's flight path (or operating area) and its corridor, in lon/lat.

    Parameters
    ----------
    corridor : Corridor or None
        ``CompileResult.corridor``: ``path`` and ``area`` in ``frame``'s metres.
    frame : LocalFrame
    """
    if corridor is None or corridor.area.is_empty:
        return []
    area, path = (frame.geom_to_wgs84(g) for g in (corridor.area, corridor.path))
    what = "flight path" if corridor.of_path else "operating area"
    rows = [("distance", f"{corridor.distance_m:g} m")]
    layers = [
        {"name": f"corridor ({corridor.distance_m:g} m)", "color": CORRIDOR_COLOR, "dash": "5 5",
         "fill": 0.05, "weight": 1.0, "legend": "corridor",
         "features": [feature(g, "corridor", rows) for g in rounded_geojson([area])]},
        {"name": what, "color": PATH_COLOR, "weight": 2.0, "legend": what,
         "features": [feature(g, what) for g in rounded_geojson([path])]},
    ]  # fmt: skip
    return layers


def route_layers(planner, route, lonlat) -> list:
    """A route (blue), its A* path (dashed), its roadmap (grey) and its ends, in lon/lat.

    Parameters
    ----------
    planner : CorridorPlanner or FenceRoadmap
        Its ``frame`` and ``roadmap`` (metres).
    route : Route
        What the planner found (metres of its frame).
    lonlat : ndarray
        The route's waypoints, ``(lon, lat)`` rows.
    """
    roadmap, frame = planner.roadmap, planner.frame
    layers = []
    V, E = np.asarray(roadmap.vertices), np.asarray(roadmap.edges)
    if len(E):
        lon, lat = frame.to_wgs84(V[:, 0], V[:, 1])
        ll = np.column_stack([lon, lat])
        segs = np.round(np.stack([ll[E[:, 0]], ll[E[:, 1]]], axis=1), DIGITS).tolist()
        geom = {"type": "MultiLineString", "coordinates": segs}
        layers.append({"name": "roadmap", "color": ROADMAP_COLOR, "weight": 0.6,
                       "legend": "roadmap", "hidden": len(E) > 20000,
                       "features": [feature(geom, "roadmap", [("edges", len(E))])]})  # fmt: skip
    if route.raw_xy is not None and len(route.raw_xy) > 1:
        lon, lat = frame.to_wgs84(route.raw_xy[:, 0], route.raw_xy[:, 1])
        layers.append({"name": "A* path", "color": ROUTE_COLOR, "dash": "4 4", "weight": 1.0,
                       "legend": "A* path (before smoothing)",
                       "features": [feature(_line(np.column_stack([lon, lat])), "A* path")]})  # fmt: skip
    rows = [("length", f"{route.length_m:,.0f} m"), ("legs", len(lonlat) - 1),
            ("least clearance", f"{route.min_clearance_m:.1f} m")]  # fmt: skip
    if route.warning_m > 0:
        rows.append(("inside warning layers", f"{route.warning_m:,.0f} m"))
    ends = [feature(_point(*lonlat[0]), "start", color="#2e7d32"),
            feature(_point(*lonlat[-1]), "goal", color="#1b5e20")]  # fmt: skip
    layers.append({"name": "route", "color": ROUTE_COLOR, "weight": 3.0, "legend": "route",
                   "features": [feature(_line(lonlat), "route", rows), *ends]})  # fmt: skip
    return layers


def leg_verdicts(result) -> dict:
    """Leg number -> its verdict (a key of :data:`LEG_COLORS`), from a
    :class:`~alphafence.review.mission_check.MissionCheck`."""
    worst = {}
    order = list(LEG_COLORS)
    for i in result.issues:
        v = ("leaves a keep-in fence" if i.keep_in else "crosses a keep-out fence") if i.crosses else "grazes a fence"  # fmt: skip
        if i.leg not in worst or order.index(v) < order.index(worst[i.leg]):
            worst[i.leg] = v
    return {n: worst.get(n, "clear") for n, _, _ in result.legs}


def mission_layers(result, clearance) -> list:
    """A mission's legs, each coloured by its verdict, with its fences and distances in the
    popup, and its waypoints.

    Parameters
    ----------
    result : MissionCheck
        What :func:`~alphafence.review.mission_check.check_mission` found.
    clearance : float
        The clearance the check used (metres).
    """
    verdicts = leg_verdicts(result)
    near = {}
    for i in result.issues:
        near.setdefault(i.leg, []).append(f"{i.fence}: {i.distance_m:.1f} m")
    legs, points = [], {}
    for n, a, b in result.legs:
        rows = [("from", a.label), ("to", b.label), ("verdict", verdicts[n])]
        if b.alt is not None:
            rows.append(("altitude at its end", f"{b.alt:g} m ({b.frame or 'home'})"))
        rows += [("fence", t) for t in near.get(n, [])[:5]]
        if n in result.warning_legs:
            rows.append(("warning layers", "passes through"))
        line = _line([(a.lon, a.lat), (b.lon, b.lat)])
        legs.append(feature(line, f"leg {n}", rows, color=LEG_COLORS[verdicts[n]]))
        for w in (a, b):
            points.setdefault((round(w.lon, DIGITS), round(w.lat, DIGITS)), w.label)
    present = [[f"leg {v}" + (f" (< {clearance:g} m)" if v == "grazes a fence" else ""), c]
               for v, c in LEG_COLORS.items() if v in verdicts.values()]  # fmt: skip
    wps = [feature(_point(*k), label, radius=4, color=PATH_COLOR) for k, label in points.items()]
    return [
        {"name": "mission legs", "color": "#2e7d32", "weight": 3.0, "legend_rows": present,
         "features": legs},
        {"name": "waypoints", "color": PATH_COLOR, "radius": 4, "legend": "waypoint",
         "features": wps},
    ]  # fmt: skip


def ramp_color(value, low, high) -> str:
    """The colour of ``value`` on :data:`RAMP` between ``low`` and ``high``.

    Examples
    --------
    >>> ramp_color(0, 0, 100), ramp_color(100, 0, 100), ramp_color(50, 50, 50)
    ('#440154', '#fde725', '#440154')
    """
    if not high > low:
        return RAMP[0]
    k = int(np.clip((value - low) / (high - low), 0, 1) * (len(RAMP) - 1) + 0.5)
    return RAMP[k]


def event_text(e) -> str:
    """One line for a monitor event: what, its level and the fences or reason it names."""
    what = str(e.get("event", "")).replace("_", " ")
    if e.get("level"):
        what += f" {e['level']}"
    for key in ("fence", "site", "fences", "reason", "message", "text"):
        v = e.get(key)
        if v:
            what += f": {', '.join(map(str, v)) if isinstance(v, list) else v}"
            break
    return what


def flight_layers(report) -> list:
    """A post-flight check's track (coloured by height above home), its start and end, the
    fences it entered and the alerts the monitor would have raised, each with its UTC time.

    Parameters
    ----------
    report : FlightReport
        What :func:`~alphafence.review.postflight.check_flight` returned.
    """
    track = np.asarray(report.track, float)
    alt = track[:, 3]
    finite = alt[np.isfinite(alt)]
    low, high = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 0.0)
    segs = []
    for k in range(len(track) - 1):  # runs of one colour, so a long track stays few lines
        color = ramp_color(np.nan_to_num((alt[k] + alt[k + 1]) / 2, nan=low), low, high)
        if segs and segs[-1][0] == color:
            segs[-1][1].append(k + 1)
        else:
            segs.append((color, [k, k + 1]))
    feats = []
    for color, idx in segs:
        a, b = track[idx[0]], track[idx[-1]]
        rows = [("from", report.when(a[0]) or f"T+{a[0]:.1f} s"),
                ("to", report.when(b[0]) or f"T+{b[0]:.1f} s"),
                ("height above home", f"{np.nanmin(track[idx, 3]):.0f} to {np.nanmax(track[idx, 3]):.0f} m")]  # fmt: skip
        feats.append(feature(_line(track[idx][:, 1:3]), "track", rows, color=color))
    ends = [feature(_point(*track[0, 1:3]), "log start", [("UTC", report.when(track[0, 0]) or "-")], color=PATH_COLOR),
            feature(_point(*track[-1, 1:3]), "log end", [("UTC", report.when(track[-1, 0]) or "-")], color="#757575")]  # fmt: skip
    layers = [{"name": "flight track", "weight": 3.0, "legend": "track, height above home",
               "ramp": {"low": f"{low:.0f} m", "high": f"{high:.0f} m", "colors": list(RAMP)},
               "features": feats + ends}]  # fmt: skip
    breaches = []
    for inc in report.incursions:
        r = report.fences.records[inc.fence]
        what = {"keep_in": "left keep-in fence", "warning": "entered warning layer"}.get(inc.kind, "entered keep-out fence")  # fmt: skip
        rows = [("UTC", report.when(inc.t_in) or f"T+{inc.t_in:.1f} s"), ("what", f"{what} {r.site_id}"),
                ("name", r.name or "-"), ("depth", f"{inc.depth_m:.1f} m"), ("altitude", f"{inc.alt_m:.1f} m"),
                ("out", "log ends" if inc.t_out is None else report.when(inc.t_out) or f"T+{inc.t_out:.1f} s")]  # fmt: skip
        color = "#ef8f00" if inc.kind == "warning" else BREACH_COLOR
        breaches.append(feature(_point(inc.lon, inc.lat), what, rows, color=color, radius=8))
    if breaches:
        layers.append({"name": "breaches", "color": BREACH_COLOR, "radius": 8,
                       "legend": "breach (fence entered or left)", "features": breaches})  # fmt: skip
    events = []
    t, lon, lat = track[:, 0], track[:, 1], track[:, 2]
    for e in report.alerts:
        k = int(np.clip(np.searchsorted(t, e["time"]), 0, len(t) - 1))
        elon, elat = e.get("lon", lon[k]), e.get("lat", lat[k])
        # the log's own clock (an event's "utc" is the engine's, not the log's)
        when = report.when(e["time"]) or f"T+{e['time']:.1f} s"
        rows = [("UTC", when), ("event", event_text(e))]
        events.append(feature(_point(elon, elat), event_text(e), rows, color=EVENT_COLOR, radius=6))
    if events:
        layers.append({"name": "events", "color": EVENT_COLOR, "radius": 6,
                       "legend": "monitor alert", "features": events})  # fmt: skip
    return layers


def fence_indices_near(report, margin_m=1000.0) -> list:
    """The indices of a report's fences within ``margin_m`` of the box around its track (the
    fences a flight's map draws)."""
    fs, track = report.fences, np.asarray(report.track, float)
    box = shapely.box(track[:, 1].min(), track[:, 2].min(), track[:, 1].max(), track[:, 2].max())
    local = shapely.buffer(fs.frame.geom_to_local(box), margin_m)
    return sorted(fs.tree.query(local, predicate="intersects").tolist())


def records_near(records, frame, xy, margin_m) -> list:
    """The fences of ``records`` within ``margin_m`` of the box around ``xy`` (metres of
    ``frame``): what a route's map draws, however large the fence file."""
    xy = np.asarray(xy, float)
    box = shapely.buffer(shapely.box(*xy.min(axis=0), *xy.max(axis=0)), margin_m)
    area = frame.geom_to_wgs84(box)
    geoms = np.array([r.geometry for r in records], dtype=object)
    hits = shapely.STRtree(geoms).query(area, predicate="intersects") if len(geoms) else []
    return [records[k] for k in sorted(np.asarray(hits).tolist())]
