"""ArduPilot's fences as fence input: its legacy fence files, and fence items (a QGC plan's
geoFence, a fence ``.waypoints`` file) read as fences.

Legacy fence files: one ``lat lon`` pair a line (tab or space separated, ``#``
comments), as MAVProxy's ``fence save`` and ArduPilot's autotest write them.

The first point is the return point; the rest is one inclusion polygon whose last point
repeats its first (ArduPilot refuses an unclosed legacy fence). It is read as one keep-in
fence, the return point kept in its properties.
"""

from __future__ import annotations

import math
import re

import shapely

from alphafence.errors import InputError
from alphafence.geo.coords import checked_position
from alphafence.mavlink.items import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    FenceItem,
    polygon_lonlat,
)
from alphafence.zones.airspace import polygonal
from alphafence.zones.jsonfile import read_limited

MAX_BYTES = 16 * 1024 * 1024  # ArduPilot holds at most a few hundred fence points
_PAIR = re.compile(r"^\s*(\S+)\s+(\S+)\s*$")


def looks_like_legacy_fence(text: str) -> bool:
    """Whether the first line that is no comment is two numbers (``lat lon``).

    Examples
    --------
    >>> looks_like_legacy_fence("# CMAC\\n-35.3637\\t149.1636\\n-35.3587\\t149.1651\\n")
    True
    >>> looks_like_legacy_fence("QGC WPL 110\\n")
    False
    """
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        m = _PAIR.match(line)
        try:
            return m is not None and all(math.isfinite(float(v)) for v in m.groups())
        except ValueError:
            return False
    return False


def read_legacy_points(path):
    """The ``(lon, lat)`` points of a legacy fence file, in file order.

    Raises
    ------
    InputError
        A line that is not two numbers, or a position out of range, naming the line.
    """
    data = read_limited(path, MAX_BYTES, "larger than a legacy fence file can be (16 MB)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not UTF-8 text (byte {exc.start})") from None
    points = []
    for n, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        where = f"line {n}"
        m = _PAIR.match(line)
        try:
            lat, lon = float(m.group(1)), float(m.group(2))
        except (AttributeError, ValueError):
            raise InputError(path, f"expected 'lat lon', got {line[:60]!r}", where) from None
        if not (math.isfinite(lat) and math.isfinite(lon)):
            raise InputError(path, f"expected 'lat lon', got {line[:60]!r}", where)
        points.append(checked_position(path, where, lat, lon))
    return points


def read_legacy_fence(path):
    """The legacy fence as one keep-in fence.

    Returns
    -------
    list of FenceRecord
        One record, ``site_id`` ``"legacy/polygon"``, ``properties["return_point"]`` the
        return point ``[lon, lat]``.

    Raises
    ------
    InputError
        Fewer than a return point and a closed triangle (5 points), or a polygon whose last
        point does not repeat its first.
    """
    from alphafence.fencefiles.fence_geojson import FenceRecord

    points = read_legacy_points(path)
    if len(points) < 5:
        raise InputError(
            path,
            f"{len(points)} points: a legacy fence is a return point and a closed polygon "
            "of at least 3 vertices (5 points)",
        )
    ret, ring = points[0], points[1:]
    if ring[-1] != ring[0]:
        raise InputError(
            path, "the last point must repeat the first polygon point (ArduPilot closes it so)"
        )
    polygon = shapely.Polygon(ring)
    if len(set(ring)) < 3 or polygon.area == 0:
        raise InputError(path, "the polygon has no area")
    if not polygon.is_valid:  # an outline that crosses itself: its area, as ArduPilot tests it
        polygon = polygonal(shapely.make_valid(polygon))
    props = {
        "site_id": "legacy/polygon",
        "kind": "keep_in",
        "category": "operating_area",
        "return_point": list(ret),
    }
    return [
        FenceRecord(
            "legacy/polygon", "keep_in", polygon, 0.0, None, "operating_area", properties=props
        )
    ]


def read_legacy_items(path):
    """The legacy fence as the items an upload sends: its return point, then its polygon as
    inclusion vertices (without the closing repeat, counter-clockwise; an outline that crosses
    itself as the polygons of its area).

    Returns
    -------
    list of FenceItem

    Raises
    ------
    InputError
        As :func:`read_legacy_fence`.
    """
    (rec,) = read_legacy_fence(path)
    items = [FenceItem(RETURN_POINT, 0.0, *rec.properties["return_point"])]
    for part in shapely.get_parts(rec.geometry):
        ring = polygon_lonlat(part)
        items.extend(FenceItem(POLYGON_INCLUSION, float(len(ring)), lon, lat) for lon, lat in ring)
    return items


def item_fences(path, items, what):
    """Fence items (a QGC plan's geoFence, a fence ``.waypoints`` file) as fences: inclusion
    polygons and circles keep-in, exclusion ones keep-out, circles kept as circles; the return
    point, if any, in every fence's properties.

    Parameters
    ----------
    path : str or Path
    items : list of FenceItem
        As ``qgc_plan.read_plan_fence`` or ``qgc_wpl.read_waypoints_fence`` return them.
    what : str
        The format, for site ids (``"plan/polygon/0"``) and messages.

    Returns
    -------
    list of FenceRecord

    Raises
    ------
    InputError
        No fence at all, or a polygon whose vertices do not say its vertex count (param1),
        naming the item.

    Examples
    --------
    >>> from alphafence.mavlink.items import FenceItem
    >>> square = [FenceItem(5001, 4.0, lon, lat) for lon, lat in
    ...           [(14.5, 35.9), (14.6, 35.9), (14.6, 36.0), (14.5, 36.0)]]
    >>> [(f.site_id, f.kind, f.circle) for f in item_fences("f.plan", square, "plan")]
    [('plan/polygon/0', 'keep_in', None)]
    """
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.zones.airspace import circle_polygon

    ret = next(([it.lon, it.lat] for it in items if it.command == RETURN_POINT), None)
    extra = {} if ret is None else {"return_point": ret}
    out, i, counts = [], 0, {"polygon": 0, "circle": 0}
    while i < len(items):
        it = items[i]
        if it.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            ring = _polygon_items(path, items, i)
            kind = "keep_in" if it.command == POLYGON_INCLUSION else "keep_out"
            geom = shapely.Polygon([(p.lon, p.lat) for p in ring])
            if not geom.is_valid:
                geom = polygonal(shapely.make_valid(geom))
            shape, i = "polygon", i + len(ring)
            circle = None
        elif it.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
            if not (math.isfinite(it.param1) and it.param1 > 0):
                raise InputError(path, f"circle radius {it.param1} is not positive", f"item {i}")
            kind = "keep_in" if it.command == CIRCLE_INCLUSION else "keep_out"
            circle = (it.lon, it.lat, float(it.param1))
            geom, shape, i = circle_polygon(*circle), "circle", i + 1
        else:
            i += 1
            continue
        if geom is None or geom.is_empty:
            raise InputError(path, "a polygon without area", f"item {i - 1}")
        site = f"{what}/{shape}/{counts[shape]}"
        counts[shape] += 1
        props = {"site_id": site, "kind": kind, **extra}
        if circle is not None:
            props.update(center=[circle[0], circle[1]], radius_m=circle[2])
        out.append(FenceRecord(site, kind, geom, 0.0, circle=circle, properties=props))
    if not out:
        raise InputError(path, "no fence polygons or circles in it (nothing to keep in or out)")
    return out


def _polygon_items(path, items, start):
    """The vertices of the polygon starting at ``items[start]``: as many as its param1 says,
    all of its command and count."""
    it = items[start]
    n = it.param1
    if not (math.isfinite(n) and n == int(n) and n >= 3):
        raise InputError(
            path,
            f"a polygon's vertex count (param1) must be a whole number >= 3, not {n:g}",
            f"item {start}",
        )
    ring = items[start : start + int(n)]
    if len(ring) < n or any(p.command != it.command or p.param1 != n for p in ring):
        raise InputError(
            path, f"a polygon of {int(n)} vertices has fewer items in a row", f"item {start}"
        )
    return ring


def onboard_kind(path):
    """``"waypoints"`` (a QGC WPL file) or ``"legacy"`` (ArduPilot's legacy fence file) for an
    onboard fence file told by its first bytes, whatever its suffix (both are often ``.txt``),
    else None (fences to compile, or no such file: their reader says so)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16).decode("latin-1")
    except OSError:
        return None
    if head.lstrip().startswith("QGC WPL"):
        return "waypoints"
    return "legacy" if looks_like_legacy_fence(head) else None
