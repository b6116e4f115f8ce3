"""Circle fences for sites that are one circle zone.

ED-269 and ED-318 circles, KML points with a radius and OpenAir ``DC`` circles are read as
circumscribed polygons (the restricted area every fence is checked against), their true
circle kept in the feature's ``circle`` property (``[lon, lat, radius_m]``). A site made of
one such zone is fenced by one circle about the zone's centre, which a vehicle stores as one
item (13 bytes) where a polygon takes one per vertex (258 bytes for a 32-gon). The circle's
radius is measured on the polygon in the site's frame, so it contains all of it: a circle
around a circle zone is as safe as the polygon fence it replaces.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

RADIUS_SLACK = 0.01  # the polygon lies within 1 % (+ 5 m) of the zone's radius, or it is no circle
RADIUS_SLACK_M = 5.0


def _zone(site):
    """``(x, y, radius_m, polygon)`` of a site that is one circle zone, else None."""
    if len(site.features) != 1 or len(site.parts) != 1:
        return None
    circle = site.features[0].properties.get("circle")
    part = site.parts[0]
    if circle is None or type(part) is not shapely.Polygon or part.is_empty:
        return None
    try:
        lon, lat, radius = (float(v) for v in circle)
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(radius) and radius > 0):
        return None
    x, y = site.frame.to_local(lon, lat)
    x, y = float(x), float(y)
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    return x, y, radius, part


def zone_circle(site, margin_m, pad_m):
    """The circle fence ``(x, y, r)`` (the site's metres) of a site that is one circle zone.

    A keep-out or warning site gets a circle about the zone's centre that contains every
    vertex of its polygon (so all of it) with ``margin_m + pad_m`` to spare; a keep-in site
    one inside its polygon, ``margin_m + pad_m`` from its edge.

    Parameters
    ----------
    site : Site
        A site of one feature whose ``properties["circle"]`` is ``[lon, lat, radius_m]``.
    margin_m : float
        The fence's margin.
    pad_m : float
        Slack for coordinate rounding (the build's ``PAD_M``).

    Returns
    -------
    tuple or None
        ``(x, y, r)``; None when the site is not one circle zone, when its polygon is not
        the zone's (farther than 1 % + 5 m from its radius), or when a keep-in circle
        vanishes inside its margin.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from alphafence.geo.frame import LocalFrame
    >>> ring = shapely.Point(0, 0).buffer(100.2, quad_segs=16)  # a polygon around the zone
    >>> zone = SimpleNamespace(properties={"circle": [14.5, 35.9, 100.0]})
    >>> site = SimpleNamespace(features=[zone], parts=[ring], kind="keep_out",
    ...                        frame=LocalFrame(14.5, 35.9))
    >>> x, y, r = zone_circle(site, 10.0, 0.1)
    >>> round(x, 6) + 0.0, round(y, 6) + 0.0, round(r, 3)
    (0.0, 0.0, 110.3)
    """
    zone = _zone(site)
    if zone is None:
        return None
    x, y, radius, part = zone
    pts = shapely.get_coordinates(part.exterior)
    far = float(np.max(np.hypot(pts[:, 0] - x, pts[:, 1] - y)))
    if far > radius * (1 + RADIUS_SLACK) + RADIUS_SLACK_M:
        return None  # not the polygon of this circle
    if site.kind == "keep_in":
        centre = shapely.Point(x, y)
        if not part.contains(centre):
            return None
        r = float(shapely.distance(centre, part.exterior)) - margin_m - pad_m
        return (x, y, r) if r > 0 else None
    # every vertex within the radius: the polygon (convex hull of its vertices) inside it
    r = far + margin_m + pad_m
    return x, y, r * (1 + 1e-9) + 1e-6
