"""Group restricted features into sites.

Features of one category and kind that overlap or lie within ``join_m`` metres of each
other form one site: a hospital campus of many buildings is one site and gets one fence.
Points and lines stand for places of unknown extent and are widened (rules' point radius
and line width) before grouping. Geometry is grouped in local metric frames: first
conservative regions from degree envelopes, then exact distances in metres per region.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import shapely

from alphafence.formats.features import make_valid_polygonal
from alphafence.geo.frame import LocalFrame

M_PER_DEG_LAT = 110_574.0
M_PER_DEG_LON = 111_320.0
SMALL_REGION_M = 20_000.0  # a region this size shares one frame: distortion < 1 mm
SMALL_GRAPH = 64  # components of graphs this small are found without scipy


@dataclass
class Site:
    """Restricted features of one category and kind close enough to share one fence.

    Attributes
    ----------
    site_id : str
        ``"<category>/<source of the largest feature>"``.
    name : str, optional
        The name of the largest named feature.
    category, kind : str
        From the rule.
    margin_m : float
        The rule's margin.
    alt_min_m, alt_max_m : float, optional
        The altitude band covering every feature's (None when one is unbounded).
    frame : LocalFrame
        The metric frame the parts are in.
    parts : ndarray of shapely geometry
        Each feature's restricted area in metres (points as discs, lines as strips).
    sources : list of str
        The features' sources, sorted.
    features : list of Feature
    """

    site_id: str
    name: str | None
    category: str
    kind: str
    margin_m: float
    alt_min_m: float | None
    alt_max_m: float | None
    frame: LocalFrame
    parts: np.ndarray  # restricted geometry per feature, metric (frame)
    sources: list
    features: list = field(repr=False, default_factory=list)

    @property
    def geometry(self):
        """The restricted area (metric): the union of the parts."""
        g = getattr(self, "_geometry", None)
        if g is None:
            g = self.parts[0] if len(self.parts) == 1 else shapely.union_all(self.parts)
            self._geometry = g
        return g


def _components(n, a, b):
    """Connected-component labels of n nodes joined by edges a-b, numbered in the order of
    each component's smallest node (as scipy numbers them)."""
    if n <= SMALL_GRAPH:  # most regions: a few features; scipy's sparse set-up costs more
        labels = np.arange(n)
        while True:  # every node takes its neighbours' least label, then its label's label
            new = labels.copy()
            np.minimum.at(new, a, labels[b])
            np.minimum.at(new, b, labels[a])
            new = new[new]
            if np.array_equal(new, labels):
                return np.unique(labels, return_inverse=True)[1]
            labels = new
    from scipy.sparse import coo_array  # scipy (the build extra), imported where it is used
    from scipy.sparse.csgraph import connected_components

    graph = coo_array((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def feature_widths(features, rules):
    """Metres each feature is widened by before grouping: the rules' point radius for points,
    half their line width for lines, 0 for areas."""
    w = np.zeros(len(features))
    for i, f in enumerate(features):
        gt = f.geomtype
        if gt == "point":
            w[i] = rules.point_radius_m
        elif gt == "line":
            w[i] = rules.line_width_m / 2.0
    return w


def _regions(geoms, widths, join_m):
    """Conservative clusters: degree envelopes grown by the join distance and widths."""
    return region_labels(shapely.bounds(geoms), widths, join_m)


def region_labels(bounds, widths, join_m):
    """Conservative clusters of features of one class, from their extents alone.

    Each extent (degrees) is grown by the join distance, twice the feature's width and a metre;
    features whose grown extents meet, directly or through others, share a region. A site never
    spans two regions, so regions can be fenced apart (in tiles, in worker processes) and give
    exactly the sites :func:`group_sites` gives.

    Parameters
    ----------
    bounds : ndarray, shape (n, 4)
        ``minlon, minlat, maxlon, maxlat`` per feature.
    widths : ndarray, shape (n,)
        Metres each feature is widened by (points and lines), else 0.
    join_m : float

    Returns
    -------
    ndarray of int
        A region label per feature.

    Examples
    --------
    >>> import numpy as np
    >>> b = np.array([[14.5, 35.9, 14.5005, 35.9004], [14.5007, 35.9, 14.5012, 35.9004],
    ...               [14.51, 35.9, 14.5105, 35.9004]])
    >>> region_labels(b, np.zeros(3), 25.0).tolist()
    [0, 0, 1]
    """
    bounds = np.asarray(bounds, dtype=float).reshape(-1, 4)
    if len(bounds) == 1:
        return np.zeros(1, int)
    lat = np.clip(np.maximum(np.abs(bounds[:, 1]), np.abs(bounds[:, 3])), 0, 89.9)
    grow_m = join_m + 2 * np.asarray(widths, dtype=float) + 1.0
    dlat = grow_m / M_PER_DEG_LAT
    dlon = grow_m / (M_PER_DEG_LON * np.cos(np.radians(lat)))
    boxes = shapely.box(
        bounds[:, 0] - dlon, bounds[:, 1] - dlat, bounds[:, 2] + dlon, bounds[:, 3] + dlat
    )
    tree = shapely.STRtree(boxes)
    a, b = tree.query(boxes, predicate="intersects")
    return _components(len(bounds), a, b)


def site_class(feature):
    """The key features are grouped by: only features with equal keys may share a site.

    Category, kind and margin (the rule's), the altitude band, and for ED-269/ED-318 zones
    their restriction, when they are in force and their vertical references
    (:func:`alphafence.formats.ed269.zone_class`): a site keeps one band, one time window and
    one reference, so a permanent zone is never switched off with an overlapping temporary
    one, nor a height limit read as an altitude.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.formats.features import Feature
    >>> from alphafence.formats.rules import load_rules
    >>> tags = {"amenity": "hospital"}
    >>> rule = load_rules().match(tags.get, "area")
    >>> site_class(Feature(shapely.box(14.5, 35.9, 14.501, 35.901), tags, "way/1", "demo", rule))
    ('hospital', 'keep_out', 30.0, None, None, ())
    """
    from alphafence.formats.ed269 import zone_class  # loaded with the database readers

    lo, hi = feature.alt_min_m, feature.alt_max_m  # to the mm: feet converted are not exact
    return (
        feature.category,
        feature.kind,
        feature.rule.margin_m,
        None if lo is None else round(lo, 3),
        None if hi is None else round(hi, 3),
        zone_class(feature.properties),
    )


def group_sites(features, rules, join_m=25.0):
    """Group restricted features into sites.

    Features of one category, kind and margin that overlap or lie within ``join_m`` metres
    of each other (points and lines widened first) form one site.

    Parameters
    ----------
    features : list of Feature
    rules : Rules
        Their point radius and line width.
    join_m : float
        Largest gap, in metres, between features of one site.

    Returns
    -------
    list of Site
        Sorted by category and site id.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.formats.features import Feature
    >>> from alphafence.formats.rules import load_rules
    >>> rules = load_rules()
    >>> hospital = rules.match({"amenity": "hospital"}.get, "area")
    >>> def ward(lon, source):  # a 45 m x 45 m building
    ...     box = shapely.box(lon, 35.9, lon + 0.0005, 35.9004)
    ...     return Feature(box, {"amenity": "hospital"}, source, "demo", hospital)
    >>> wards = [ward(14.5, "way/1"), ward(14.5007, "way/2"), ward(14.51, "way/3")]
    >>> [(s.site_id, s.sources) for s in group_sites(wards, rules)]  # 18 m apart, then 700 m
    [('hospital/way/1', ['way/1', 'way/2']), ('hospital/way/3', ['way/3'])]
    """
    by_class = defaultdict(list)
    for f in features:
        by_class[site_class(f)].append(f)
    sites = []
    for _key, feats in sorted(by_class.items(), key=lambda kv: kv[0][:2]):
        geoms = np.array([f.geometry for f in feats], dtype=object)
        widths = feature_widths(feats, rules)
        regions = _regions(geoms, widths, join_m)
        for r in np.unique(regions):
            idx = np.flatnonzero(regions == r)
            sites.extend(_region_sites([feats[i] for i in idx], geoms[idx], widths[idx], join_m))
    sites.sort(key=lambda s: (s.category, s.site_id))
    return sites


def region_sites(features, rules, join_m=25.0):
    """The sites of one region (features of one class, as :func:`region_labels` groups them,
    in the database's order): what :func:`group_sites` makes of that region.

    Parameters
    ----------
    features : list of Feature
    rules : Rules
    join_m : float

    Returns
    -------
    list of Site
    """
    geoms = np.array([f.geometry for f in features], dtype=object)
    return _region_sites(features, geoms, feature_widths(features, rules), join_m)


def _region_sites(feats, geoms, widths, join_m):
    category, kind, margin = feats[0].category, feats[0].kind, feats[0].rule.margin_m
    frame = LocalFrame.around(geoms)
    local = make_valid_polygonal(frame.geom_to_local(geoms))
    # points and lines become discs and strips; polygons stay as they are
    widened = _widen(local, widths)
    if len(widened) == 1:
        labels = np.zeros(1, int)
    else:
        tree = shapely.STRtree(widened)
        a, b = tree.query(widened, predicate="dwithin", distance=join_m)
        labels = _components(len(widened), a, b)
    extent = _extent_m(local)
    out = []
    for lab in np.unique(labels):
        idx = np.flatnonzero(labels == lab)
        members = [feats[i] for i in idx]
        parts = widened[idx]
        site_frame = frame
        if extent > SMALL_REGION_M:
            site_frame = LocalFrame.around(geoms[idx])
            loc = make_valid_polygonal(site_frame.geom_to_local(geoms[idx]))
            w = widths[idx]
            parts = _widen(loc, w)
        out.append(_make_site(category, kind, margin, site_frame, members, parts))
    return out


def _widen(local, widths):
    """Points become discs and lines strips (polygons that contain the true round shapes);
    polygons stay as they are."""
    if not np.any(widths > 0):
        return local
    grown = shapely.buffer(local, widths * circle_steps(8), quad_segs=8)
    return np.where(widths > 0, grown, local)


def _extent_m(local):
    b = shapely.total_bounds(local)
    return float(max(abs(b[0]), abs(b[1]), abs(b[2]), abs(b[3])))


def _make_site(category, kind, margin, frame, members, parts):
    areas = shapely.area(parts)
    # features within a billionth of the largest count as equally large, and the first of
    # them in the database's order names the site: not the last digits of a projection
    key = np.where(areas >= areas.max() * (1 - 1e-9), np.inf, areas)
    order = np.argsort(-key, kind="stable")
    largest = members[int(order[0])]
    name = next((members[i].name for i in order if members[i].name), None)
    alt_min = [f.alt_min_m for f in members]
    alt_max = [f.alt_max_m for f in members]
    return Site(
        site_id=f"{category}/{largest.source}",
        name=name,
        category=category,
        kind=kind,
        margin_m=margin,
        alt_min_m=None if any(a is None for a in alt_min) else min(alt_min),
        alt_max_m=None if any(a is None for a in alt_max) else max(alt_max),
        frame=frame,
        parts=parts,
        sources=sorted({f.source for f in members}),
        features=members,
    )


def circle_steps(quad_segs: int) -> float:
    """Factor by which a buffer drawn with ``quad_segs`` segments per quarter circle must be
    grown so that its chords lie outside the true round buffer.

    GEOS rounds the number of fillet segments to the nearest integer, so one chord may span
    up to 1.5 times the nominal angle (pi / 2 / quad_segs); its midpoint then lies at
    cos(half that angle) of the radius.

    Examples
    --------
    >>> round(circle_steps(8), 4)
    1.0109
    """
    return 1.0 / math.cos(1.5 * math.pi / (4 * quad_segs))
