"""KML and KMZ (Google Earth, QGroundControl's KML import, national drone-zone exports such as
the UK's 3D airspace KMZ), read with lxml (the ``kml`` extra).

Each Placemark's Polygon, LinearRing, LineString or Point (alone or in a MultiGeometry) makes
volumes. Altitudes come from the coordinates when ``altitudeMode`` is ``absolute`` (AMSL) or
``relativeToGround`` (AGL); ``clampToGround`` (the default) has none:

* an extruded geometry reaches down to the ground: the band is ground up to its highest point;
* the other polygons of a placemark are one volume: their footprints united (vertical walls,
  which have no footprint, only add their altitudes), the band from the lowest to the highest
  coordinate; a flat polygon (one altitude) has no band (a keep-out at every height);
* a zone drawn as separate placemarks (floor, ceiling and each wall its own placemark, all
  named after the zone, in one Folder) is one volume (:mod:`alphafence.zones.kml_volumes`).

Google Earth draws a polygon's edges (and a tessellated LinearRing's) along geodesics (great
circles), where GeoJSON, ED-269 and the kit join vertices with straight lines in lon/lat;
over a long edge the two part by about ``L**2 * tan(lat) / (8 * R)`` (145 m for a 60 km
edge along the parallel at 64°N). A polygon with an edge whose readings lie more than 5 cm
apart is held under both (:mod:`alphafence.zones.kml_geodesic`): a keep-out or warning
zone is their union, a keep-in zone their intersection, each edge's geodesic followed to
within 5 cm (the kit then reads the result with lon/lat edges, as everywhere). Polygons
whose edges are all shorter (along a parallel: under 1.1 km at 64°N, 1.4 km at 52°N, 1.9 km
at 36°N) come back as written. Points with a radius and lines are read as they are.

Pseudo-tags for the rules: ``airspace:format`` (``kml``), ``name``, ``kml:style`` (the
styleUrl without ``#``), ``kml:folder`` (the innermost Folder's name), ``airspace:class`` (an
ExtendedData ``class``), and every ExtendedData field by its name (``alphafence:kind =
keep_in`` makes an operating area). A Point with an ExtendedData ``radius`` (metres) is a
circle. A KMZ is a zip: its ``doc.kml`` (else its first ``.kml``) is read, never more than
``ALPHAFENCE_MAX_JSON_MB`` however well it compresses.
"""

from __future__ import annotations

import math
import re

import numpy as np
import shapely
from shapely.errors import ShapelyError

from alphafence.errors import InputError, need
from alphafence.zones.airspace import features_from_volumes
from alphafence.zones.features import settle_faults
from alphafence.zones.jsonfile import max_json_bytes, read_limited
from alphafence.zones.kml_geodesic import both_readings, geodesic_reading
from alphafence.zones.kml_volumes import Placemark, volumes

SUFFIXES = (".kml", ".kmz")
MAX_KMZ_ENTRIES = 10_000
_GEOMETRIES = ("Point", "LineString", "LinearRing", "Polygon", "MultiGeometry")
_CLASS_KEYS = ("airspace:class", "class", "airspace_class", "airspaceclass")


def looks_like_kml(head: bytes) -> bool:
    """Whether the first bytes of a file are a KMZ (zip) or a KML document.

    Examples
    --------
    >>> looks_like_kml(b'<?xml version="1.0"?><kml xmlns="http://www.opengis.net/kml/2.2">')
    True
    >>> looks_like_kml(b'{"type": "FeatureCollection"}')
    False
    """
    return head[:4] == b"PK\x03\x04" or b"<kml" in head[:1024]


def read_document(path):
    """The parsed KML document of a ``.kml`` or ``.kmz`` file (its root element).

    Raises
    ------
    InputError
        Unreadable, too large, not a zip or without a ``.kml`` inside (KMZ), malformed XML or
        not KML, in one line.
    MissingDependency
        lxml is not installed.
    """
    need(("lxml.etree", f"reading {path}"))
    from lxml import etree

    limit = max_json_bytes()
    data = read_limited(path, limit, "larger than ALPHAFENCE_MAX_JSON_MB")
    if data[:4] == b"PK\x03\x04" or str(path).lower().endswith(".kmz"):
        data = _kmz_document(path, limit)
    parser = etree.XMLParser(
        resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False
    )
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise InputError(path, f"malformed XML at line {exc.lineno}: {exc.msg}") from None
    except ValueError as exc:  # e.g. an encoding lxml does not know
        raise InputError(path, f"malformed XML ({exc})") from None
    if _local(root) != "kml":
        raise InputError(path, f"not a KML document (its root is <{_local(root)}>, not <kml>)")
    return root


def _kmz_document(path, limit):
    import zipfile
    import zlib

    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            if len(infos) > MAX_KMZ_ENTRIES:
                raise InputError(path, f"a KMZ of {len(infos)} files (at most {MAX_KMZ_ENTRIES})")
            kmls = [i for i in infos if i.filename.lower().endswith(".kml") and not i.is_dir()]
            if not kmls:
                raise InputError(path, "a KMZ without a .kml document inside")
            root = [i for i in kmls if "/" not in i.filename]
            doc = next((i for i in kmls if i.filename.lower() == "doc.kml"), (root or kmls)[0])
            if doc.file_size > limit:
                raise InputError(path, f"{doc.filename} is larger than ALPHAFENCE_MAX_JSON_MB")
            with zf.open(doc) as fh:
                data = fh.read(limit + 1)  # whatever the header says: never more than this
    except (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError) as exc:
        raise InputError(path, f"not a readable KMZ (zip) archive ({exc})") from None
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc})") from None
    if len(data) > limit:
        raise InputError(path, f"{doc.filename} is larger than ALPHAFENCE_MAX_JSON_MB")
    return data


def _local(el):
    tag = el.tag
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _children(el, name):
    return [c for c in el if _local(c) == name]


def _text(el, name):
    for c in el:
        if _local(c) == name:
            return (c.text or "").strip() or None
    return None


def placemarks(root):
    """``(placemark element, innermost Folder element or None)`` of every Placemark, in
    document order (inside Documents and Folders at any depth)."""
    out = []
    for el in root.iter():
        if _local(el) == "Placemark":
            folders = (a for a in el.iterancestors() if _local(a) == "Folder")
            out.append((el, next(folders, None)))
    return out


def _coordinates(path, label, el):
    """An (n, 3) array (altitude NaN where absent) from a ``<coordinates>`` element's text."""
    text = re.sub(r"\s*,\s*", ",", (el.text or "").strip())
    rows = []
    for token in text.split():
        fields = token.split(",")
        try:
            values = [float(v) for v in fields]
        except ValueError:
            values = []
        if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
            raise InputError(path, f"malformed coordinates {token[:60]!r}", label)
        rows.append(values if len(values) == 3 else [*values, math.nan])
    if not rows:
        raise InputError(path, "empty coordinates", label)
    return np.array(rows, float)


def _ring(path, label, el):
    """The coordinates of the LinearRing inside ``el`` (or of ``el`` itself). A ring of
    fewer than four coordinates (a face drawn edge-on: two points and back) is kept as a face
    without area, its last point repeated: a volume takes its footprint from its other faces."""
    ring = el if _local(el) == "LinearRing" else next(iter(_children(el, "LinearRing")), None)
    coords = None if ring is None else next(iter(_children(ring, "coordinates")), None)
    if coords is None:
        raise InputError(path, "a ring without coordinates", label)
    rows = _coordinates(path, label, coords)
    if len(rows) < 4:
        rows = np.vstack([rows, np.repeat(rows[-1:], 4 - len(rows), axis=0)])
    return rows


def _primitives(path, label, el, out):
    """(kind, shapely 2-D geometry, z values, altitudeMode, extrude) of a geometry element."""
    name = _local(el)
    if name == "MultiGeometry":
        for child in el:
            if _local(child) in _GEOMETRIES:
                _primitives(path, label, child, out)
        return
    mode = _text(el, "altitudeMode") or "clampToGround"
    extrude = (_text(el, "extrude") or "0").lower() in ("1", "true")
    try:
        if name == "Polygon":
            outer = [_ring(path, label, b) for b in _children(el, "outerBoundaryIs")]
            if len(outer) != 1:
                raise InputError(path, "a Polygon needs one outerBoundaryIs", label)
            inners = [
                _ring(path, label, r)
                for b in _children(el, "innerBoundaryIs")
                for r in _children(b, "LinearRing")
            ]
            geom = shapely.Polygon(outer[0][:, :2], [h[:, :2] for h in inners])
            zs = np.concatenate([outer[0][:, 2], *[h[:, 2] for h in inners]])
            out.append(("area", geom, zs, mode, extrude))
        elif name == "LinearRing":
            coords = _ring(path, label, el)
            out.append(("area", shapely.Polygon(coords[:, :2]), coords[:, 2], mode, extrude))
        else:
            node = next(iter(_children(el, "coordinates")), None)
            if node is None:
                raise InputError(path, f"a {name} without coordinates", label)
            coords = _coordinates(path, label, node)
            if name == "Point":
                geom = shapely.Point(coords[0, :2])
            else:
                geom = shapely.LineString(coords[:, :2])
            out.append(("point" if name == "Point" else "line", geom, coords[:, 2], mode, extrude))
    except (ShapelyError, ValueError) as exc:
        raise InputError(path, f"malformed {name} ({exc})", label) from None


def _radius(path, label, ext):
    value = ext.get("radius", ext.get("radius_m"))
    if value is None:
        return None
    try:
        r = float(value)
    except ValueError:
        r = math.nan
    if not (math.isfinite(r) and r > 0):
        raise InputError(path, f"radius must be a positive number of metres, not {value!r}", label)
    return r


def _extended(pm):
    """ExtendedData fields by name: ``<Data name><value>`` and ``<SimpleData name>``."""
    out = {}
    for ext in _children(pm, "ExtendedData"):
        for data in ext.iter():
            name = data.get("name") if isinstance(data.tag, str) else None
            if not name:
                continue
            if _local(data) == "Data":
                value = _text(data, "value")
            elif _local(data) == "SimpleData":
                value = (data.text or "").strip() or None
            else:
                continue
            if value is not None:
                out[name] = value
    return out


def _tags(name, style, folder, ext):
    tags = {k: v for k, v in ext.items()}
    tags["airspace:format"] = "kml"
    for key, value in (("name", name), ("kml:style", style), ("kml:folder", folder)):
        if value:
            tags[key] = value
    cls = next((v for k, v in ext.items() if k.lower() in _CLASS_KEYS), None)
    if cls:
        tags["airspace:class"] = cls
    return tags


def _placemark(path, index, pm, folder, skipped):
    """A Placemark's geometries and names, or None (counted) when it has no geometry."""
    name = _text(pm, "name")
    label = f"placemark {index}" + (f" ({name})" if name else "")
    style = _text(pm, "styleUrl")
    style = style.rsplit("#", 1)[-1] if style else None
    ext = _extended(pm)
    tags = _tags(name, style, folder if folder is None else _text(folder, "name"), ext)
    prims = []
    for el in pm:
        if _local(el) in _GEOMETRIES:
            _primitives(path, label, el, prims)
    if not prims:
        if skipped is not None:
            skipped["KML placemark without a Polygon, LinearRing, LineString or Point"] += 1
        return None
    radius = _radius(path, label, ext) if any(p[0] == "point" for p in prims) else None
    ident = pm.get("id") or f"placemark/{index}"
    return Placemark(index, label, name, folder, ident, tags, prims, radius)


def read_volumes(path, skipped=None, invalid=None):
    """The placemarks of a KML or KMZ file as volumes (see :mod:`alphafence.zones.airspace`),
    their polygons' edges straight in lon/lat, and how each is held read both ways.

    Parameters
    ----------
    path : str or Path
    skipped : collections.Counter, optional
        Placemarks without a geometry read here are counted.
    invalid : list, optional
        When given, malformed placemarks are left out and described here (``file``,
        ``airspace``: the placemark, ``problem``); when None, all of them are raised at once.

    Returns
    -------
    volumes : list of tuple
    readings : list
        One per volume: None when its edges read alike both ways, else the ``(keep_out,
        keep_in)`` areas (:func:`alphafence.zones.kml_geodesic.both_readings`).

    Raises
    ------
    InputError
        One line naming the placemark that is malformed.
    """
    root = read_document(path)
    marks, faults = [], []
    for k, (pm, folder) in enumerate(placemarks(root)):
        try:
            marks.append(_placemark(path, k, pm, folder, skipped))
        except InputError as exc:  # every placemark's fault, not only the first
            faults.append(exc)
    marks = [m for m in marks if m is not None]
    straight = volumes(path, marks, faults=faults)
    settle_faults(path, faults, invalid)  # one fault is its own line; several, each on its own
    areas = [p[1] for pm in marks for p in pm.prims if p[0] == "area"]
    geodesic = {id(g): geodesic_reading(g) for g in areas}
    if all(geodesic[id(g)] is g for g in areas):
        return straight, [None] * len(straight)
    read = volumes(path, marks, lambda g: geodesic[id(g)], faults=[])  # the same faults
    readings = [None if a[0] is b[0] else both_readings(a[0], b[0]) for a, b in zip(straight, read)]
    return straight, readings


def read_kml(path, rules, repaired, skipped, invalid=None):
    """The restricted features of a KML or KMZ file, matched against ``rules`` by the
    pseudo-tags above (by default every zone is a keep-out ``airspace``).

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        One line naming the placemark that is malformed.
    MissingDependency
        lxml is not installed.
    """
    volumes, readings = read_volumes(path, skipped, invalid)
    what = "KML placemark"
    return features_from_volumes(path, volumes, rules, repaired, skipped, what, readings)
