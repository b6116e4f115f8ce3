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

from alphafence.fencing.regions import _components, region_labels
from alphafence.geo.frame import LocalFrame
from alphafence.geo.lonlat import densify_lonlat
from alphafence.zones.features import make_valid_polygonal

SMALL_REGION_M = 20_000.0  # a region this size shares one frame: distortion < 1 mm


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


def site_class(feature):
    """The key features are grouped by: only features with equal keys may share a site.

    Category, kind and margin (the rule's), the altitude band, and for ED-269/ED-318 zones
    their restriction, when they are in force and their vertical references
    (:func:`alphafence.zones.ed269.zone_class`): a site keeps one band, one time window and
    one reference, so a permanent zone is never switched off with an overlapping temporary
    one, nor a height limit read as an altitude.

    Examples
    --------
    >>> import shapely
    >>> from alphafence.zones.features import Feature
    >>> from alphafence.zones.rules import load_rules
    >>> tags = {"amenity": "hospital"}
    >>> rule = load_rules().match(tags.get, "area")
    >>> site_class(Feature(shapely.box(14.5, 35.9, 14.501, 35.901), tags, "way/1", "demo", rule))
    ('hospital', 'keep_out', 30.0, None, None, ())
    """
    from alphafence.zones.ed269 import zone_class  # loaded with the database readers

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
    >>> from alphafence.zones.features import Feature
    >>> from alphafence.zones.rules import load_rules
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
        # region by region, each in its features' canonical order (by source): a site is
        # made of its features whatever order the database gave them in, so an update that
        # rebuilds one region gives the bits a whole build gives
        labels = regions.tolist()
        order = np.array(sorted(range(len(feats)), key=lambda i: (labels[i], feats[i].source)))
        ends = np.cumsum(np.bincount(regions))
        spans = list(zip([0, *ends[:-1].tolist()], ends.tolist()))
        sites.extend(
            _regions_sites([feats[i] for i in order], geoms[order], widths[order], spans, join_m)
        )
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
    return regions_sites(features, [(0, len(features))], rules, join_m)


def regions_sites(features, spans, rules, join_m=25.0):
    """The sites of many regions at once: :func:`region_sites` of each span of ``features``,
    in order, the same sites (bit for bit), with each step run once over all the regions
    where it works feature by feature (reprojection, repair, widening, areas).

    Parameters
    ----------
    features : list of Feature
        The regions' features, region after region.
    spans : list of tuple
        ``(start, end)`` of each region in ``features``.
    rules : Rules
    join_m : float

    Returns
    -------
    list of Site

    Examples
    --------
    >>> import shapely
    >>> from alphafence.zones.features import Feature
    >>> from alphafence.zones.rules import load_rules
    >>> rules = load_rules()
    >>> rule = rules.match({"amenity": "school"}.get, "area")
    >>> def school(lon, source):
    ...     box = shapely.box(lon, 35.9, lon + 0.0005, 35.9004)
    ...     return Feature(box, {"amenity": "school"}, source, "demo", rule)
    >>> feats = [school(14.5, "way/1"), school(14.6, "way/2"), school(14.6007, "way/3")]
    >>> [s.sources for s in regions_sites(feats, [(0, 1), (1, 3)], rules)]
    [['way/1'], ['way/2', 'way/3']]
    """
    order = canonical_order(features, spans)
    features = [features[i] for i in order]
    geoms = np.array([f.geometry for f in features], dtype=object)
    return _regions_sites(features, geoms, feature_widths(features, rules), spans, join_m)


def canonical_order(features, spans):
    """The order each span's features are grouped in: by source, then as given (a database's
    order does not decide a site's name, its largest feature or the bits of its fence).

    Examples
    --------
    >>> from types import SimpleNamespace as F
    >>> canonical_order([F(source="way/2"), F(source="node/9"), F(source="way/1")], [(0, 2), (2, 3)])
    [1, 0, 2]
    """
    out = []
    for start, end in spans:
        out.extend(sorted(range(start, end), key=lambda i: features[i].source))
    return out


def _regions_sites(feats, geoms, widths, spans, join_m):
    geoms = densify_lonlat(geoms)  # long edges followed along their lon/lat lines
    counts = shapely.get_num_coordinates(geoms)
    if not len(spans) or np.any(counts == 0) or np.any(shapely.has_z(geoms)):
        out = []  # the general path, region by region (empty or 3-D geometry)
        for start, end in spans:
            out.extend(_region_sites(feats[start:end], geoms[start:end], widths[start:end], join_m))
        return out
    frames = _frames(geoms, counts, spans)
    starts = np.array([s for s, _ in spans])
    # each coordinate in its region's frame: the numbers region-by-region reprojection gives
    at = np.concatenate([[0], np.cumsum(counts)])[[*starts.tolist(), spans[-1][1]]].tolist()

    def forward(coords):
        out = np.empty_like(coords)
        for frame, a, b in zip(frames, at[:-1], at[1:]):
            out[a:b] = frame._fwd(coords[a:b])
        return out

    local = make_valid_polygonal(shapely.transform(geoms, forward))
    widened = _widen(local, widths)
    areas = shapely.area(widened)
    reach = np.fmax.reduce(np.abs(shapely.bounds(local)), axis=1)  # NaN where empty
    out = []
    for (start, end), frame in zip(spans, frames):
        members = feats[start:end]
        cut = slice(start, end)
        out.extend(
            _sites_of(
                members,
                geoms[cut],
                widths[cut],
                local[cut],
                widened[cut],
                areas[cut],
                frame,
                float(np.fmax.reduce(reach[cut])),  # _extent_m of the region
                join_m,
            )
        )
    return out


def _frames(geoms, counts, spans):
    """Each region's :meth:`LocalFrame.around` frame, the centres found for all at once."""
    coords = shapely.get_coordinates(geoms)
    ends = np.cumsum(counts)
    first = np.concatenate([[0], ends])[[s for s, _ in spans]]
    lo = np.minimum.reduceat(coords, first)
    hi = np.maximum.reduceat(coords, first)
    frames = []
    last = [*first[1:].tolist(), len(coords)]
    for k, a in enumerate(first.tolist()):
        if hi[k, 0] - lo[k, 0] > 180.0:  # wraps the antimeridian: as around_coords does
            frames.append(LocalFrame.around_coords(coords[a : last[k]]))
        else:
            frames.append(LocalFrame(0.5 * (lo[k, 0] + hi[k, 0]), 0.5 * (lo[k, 1] + hi[k, 1])))
    return frames


def _region_sites(feats, geoms, widths, join_m):
    frame = LocalFrame.around(geoms)
    local = make_valid_polygonal(frame.geom_to_local(geoms))
    # points and lines become discs and strips; polygons stay as they are
    widened = _widen(local, widths)
    return _sites_of(
        feats, geoms, widths, local, widened, shapely.area(widened), frame, _extent_m(local), join_m
    )


def _sites_of(feats, geoms, widths, local, widened, areas, frame, extent, join_m):
    """A region's sites from its features in its frame (``local``), widened, and their
    areas; ``extent``, metres from the frame's origin to the region's farthest bound."""
    category, kind, margin = feats[0].category, feats[0].kind, feats[0].rule.margin_m
    if len(widened) == 1:
        groups = [np.zeros(1, int)]
    else:
        tree = shapely.STRtree(widened)
        a, b = tree.query(widened, predicate="dwithin", distance=join_m)
        labels = _components(len(widened), a, b)
        groups = [np.flatnonzero(labels == lab) for lab in np.unique(labels)]
    out = []
    for idx in groups:
        members = [feats[i] for i in idx]
        parts, part_areas = widened[idx], areas[idx]
        site_frame = frame
        if extent > SMALL_REGION_M:
            site_frame = LocalFrame.around(geoms[idx])
            loc = make_valid_polygonal(site_frame.geom_to_local(geoms[idx]))
            parts = _widen(loc, widths[idx])
            part_areas = shapely.area(parts)
        out.append(_make_site(category, kind, margin, site_frame, members, parts, part_areas))
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


def _make_site(category, kind, margin, frame, members, parts, areas):
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
