"""What a built fence is (:class:`Fence`, in its site's metric frame) and how fences are made
(:class:`FenceOptions`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from alphafence.geo.lonlat import frame_scale


@dataclass
class FenceOptions:
    """How fences are made.

    Attributes
    ----------
    method : str
        ``"alpha"`` (alpha shape), ``"polygon"`` (convex hull), ``"circle"`` or ``"exact"``
        (the required region itself).
    alpha_radius : float, optional
        Alpha in metres; None picks the smallest that joins each site into one piece.
    max_vertices : int
        Simplify (outward) to at most this many vertices a polygon.
    tolerance_m : float
        Simplifications adding at most this much height always run.
    warn_distance_m : float
        Width of the warning layer around keep-out fences (0: none).
    margin_m : float, optional
        Overrides every rule's margin (0 is the paper's setting).
    max_overshoot_m : float, optional
        No simplified fence reaches farther than this beyond the shape its method drew
        (more vertices than ``max_vertices`` where needed); None: the budget alone.
    """

    method: str = "alpha"
    alpha_radius: float | None = None  # metres; None = automatic per site
    max_vertices: int = 32
    tolerance_m: float = 1.0
    warn_distance_m: float = 30.0
    margin_m: float | None = None  # overrides every rule's margin (0 = the paper's setting)
    max_overshoot_m: float | None = None  # bounds simplification by distance, not only count


@dataclass
class Fence:
    """A fence around a site, in the site's metric frame.

    Attributes
    ----------
    site_id, name, category : str
        From the site.
    kind : str
        ``"keep_out"``, ``"keep_in"`` or ``"warning"``.
    method : str
        How it was made (``FenceOptions.method``).
    margin_m : float
        Least distance from the restricted area to the fence's boundary.
    alt_min_m, alt_max_m : float, optional
        The altitude band it applies to.
    sources : list of str
    frame : LocalFrame
    local : shapely.Polygon or shapely.MultiPolygon
        The fence, metres.
    circle : tuple, optional
        ``(x, y, radius)`` in metres, for a circle fence.
    alpha_m : float, optional
        The alpha used.
    repaired : bool
        The fence failed its containment check and was united with the required region.
    properties : dict
        ED-269 restriction, reasons, references and applicability, when the features had them.
    growth : float
        Its area over the area of its restricted area plus margin (1 for a fence that is
        that region; the build's summary names fences far larger).
    wgs84 : shapely geometry, optional
        Its lon/lat geometry when it is not ``local``'s vertices transformed: a fence across
        the antimeridian, split into a part on each side.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.geo.frame import LocalFrame
    >>> fence = Fence("hospital/way/1", None, "hospital", "keep_out", "exact", 30.0, None, None,
    ...               ["way/1"], LocalFrame(14.5, 35.9), shapely.box(-50, -50, 50, 50))
    >>> fence.vertices, fence.area_m2
    (4, 10000.0)
    >>> round(fence.geometry.bounds[0], 6)
    14.499446
    """

    site_id: str
    name: str | None
    category: str
    kind: str  # keep_out | keep_in | warning
    method: str
    margin_m: float
    alt_min_m: float | None
    alt_max_m: float | None
    sources: list
    frame: object
    local: object  # metric Polygon / MultiPolygon
    circle: tuple | None = None  # (x, y, radius) metric, for circle fences
    alpha_m: float | None = None
    repaired: bool = False
    properties: dict = field(default_factory=dict)
    growth: float = 1.0
    wgs84: object = None

    @property
    def geometry(self):
        """The fence in WGS84 (lon, lat)."""
        if self.wgs84 is not None:
            return self.wgs84
        g = getattr(self, "_wgs84", None)
        if g is None:
            g = self.frame.geom_to_wgs84(self.local)
            self._wgs84 = g
        return g

    @property
    def vertices(self) -> int:
        """Vertices of its outer rings (1 for a circle)."""
        if self.circle is not None:
            return 1
        if type(self.local) is shapely.Polygon and not self.local.is_empty:
            return int(shapely.get_num_points(self.local.exterior)) - 1
        rings = shapely.get_exterior_ring(shapely.get_parts(self.local))
        return int(np.sum(shapely.get_num_points(rings) - 1))

    @property
    def area_m2(self) -> float:
        """Its area, square metres (a circle's true area)."""
        if self.circle is not None:
            return math.pi * self.circle[2] ** 2
        return float(self.local.area)

    @property
    def circle_wgs84(self):
        """(lon, lat, radius_m) of a circle fence, else None: the geodesic circle that holds
        the frame's circle (keep-out) or lies inside it (keep-in). The frame reads distances
        across its radius up to :func:`~alphafence.geo.lonlat.frame_scale` times too long,
        so a keep-out's radius grows by that scale and a keep-in's shrinks by it."""
        if self.circle is None:
            return None
        x, y, r = self.circle[:3]
        lon, lat = self.frame.to_wgs84(x, y)
        k = frame_scale(math.hypot(x, y) + r)
        return float(lon), float(lat), float(r / k if self.kind == "keep_in" else r * k)
