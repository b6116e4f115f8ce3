"""KML airspace exports that draw each volume as separate placemarks (a floor, a ceiling and
one per vertical wall, all named after the zone, in a Folder, altitudes AMSL): one volume per
zone, checked against an independent parse of the same file (xml.etree; geodesics from pyproj)."""

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from alphafence.errors import InputError
from alphafence.fencefiles.fence_read import read_fence_file
from alphafence.zones.database import read_database
from tests.test_kml_great_circles import assert_held_both_ways

SAMPLE = Path(__file__).parent / "data" / "kml" / "separate-placemark-volumes.kml"
K = "{http://www.opengis.net/kml/2.2}"


def zones(root):
    """Independent parse: (folder name, zone name) -> (index of each placemark, its ring of
    (lon, lat, alt)), grouped by innermost Folder element and name, in document order."""
    out, index = {}, {}
    for k, pm in enumerate(root.iter(f"{K}Placemark")):
        index[pm] = k
    for folder in root.iter(f"{K}Folder"):
        for pm in folder.findall(f"{K}Placemark"):
            text = pm.find(f".//{K}coordinates").text
            ring = [tuple(map(float, t.split(","))) for t in text.split()]
            key = (folder.findtext(f"{K}name"), pm.findtext(f"{K}name"))
            out.setdefault(key, []).append((index[pm], ring))
    return out


def horizontal(ring):
    return len({z for *_, z in ring}) == 1


def expected_rings(parts):
    """The rings of the floor/ceiling polygons (united, they are the area); with walls alone,
    the ring of their base points, each wall starting where the one before it ended."""
    flats = [[(x, y) for x, y, _ in r] for _, r in parts if horizontal(r)]
    if flats:
        return flats
    bases = [[(x, y) for x, y, z in r if z == min(c[2] for c in r)] for _, r in parts]
    starts, ends = [b[0] for b in bases], [b[1] for b in bases]  # a wall's base: its first two
    assert ends == starts[1:] + starts[:1]  # the walls close their ring
    return [starts + starts[:1]]


def test_each_zone_is_one_volume_from_floor_to_ceiling(rules):
    truth = zones(ET.parse(SAMPLE).getroot())
    db = read_database([SAMPLE], rules)
    got = {(f.tags["kml:folder"], f.name): f for f in db.features}
    assert len(db.features) == len(truth) == 4  # one name in two folders: two zones
    for key, parts in truth.items():
        f = got[key]
        zs = [z for _, ring in parts for *_, z in ring]
        assert (f.alt_min_m, f.alt_max_m) == (min(zs), max(zs))
        assert f.properties["lower_reference"] == f.properties["upper_reference"] == "AMSL"
        # edges of 4-6 km at 52°N: Google Earth's geodesics part from the lon/lat lines
        assert assert_held_both_ways(f.geometry, expected_rings(parts)) > 0.3, key
        assert f.kind == "keep_out" and f.category == "airspace"
        assert f.tags["kml:style"] == ("floorStyle" if horizontal(parts[0][1]) else "wallStyle")
    assert any(not any(horizontal(r) for _, r in parts) for parts in truth.values())  # walls only


def test_the_zones_read_as_fences_and_from_a_kmz(tmp_path, rules):
    fences = read_fence_file(SAMPLE)
    truth = zones(ET.parse(SAMPLE).getroot())
    assert len(fences) == len(truth)
    bands = sorted((r.alt_min_m, r.alt_max_m) for r in fences)
    expect = [[z for _, ring in parts for *_, z in ring] for parts in truth.values()]
    assert bands == sorted((min(zs), max(zs)) for zs in expect)
    kmz = tmp_path / "airspace.kmz"
    with zipfile.ZipFile(kmz, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(SAMPLE, "doc.kml")
    a, b = (read_database([p], rules).features for p in (SAMPLE, kmz))
    assert [(f.name, f.alt_min_m, f.geometry.wkb) for f in a] == [
        (f.name, f.alt_min_m, f.geometry.wkb) for f in b
    ]


def test_walls_alone_that_close_no_ring_are_one_line_naming_the_placemark(tmp_path, rules):
    root = ET.parse(SAMPLE)
    truth = zones(root.getroot())
    (key, parts), *_ = [(k, p) for k, p in truth.items() if not horizontal(p[0][1])]
    gone = parts[2][0]  # drop one wall of the zone drawn with walls alone
    for folder in root.getroot().iter(f"{K}Folder"):
        for pm in folder.findall(f"{K}Placemark"):
            if list(root.getroot().iter(f"{K}Placemark")).index(pm) == gone:
                folder.remove(pm)
    path = tmp_path / "open.kml"
    root.write(path, xml_declaration=True, encoding="UTF-8")
    with pytest.raises(InputError) as err:
        read_database([path], rules)
    message = str(err.value)
    assert "\n" not in message
    assert message == (
        f"{path}: placemark {parts[0][0]} ({key[1]}): vertical walls whose horizontal lines "
        "close no ring, and no floor or ceiling"
    )


def test_a_flat_polygon_without_area_is_still_refused(tmp_path, rules):
    """A polygon without area whose altitudes do not vary is no wall (and no zone)."""
    text = SAMPLE.read_text()
    start = text.index("<Placemark>", text.index("Wall 1") - 200)
    end = text.index("</Placemark>", start) + len("</Placemark>")
    wall = text[start:end]
    flat = wall.replace(",609.6", ",152.4").replace("EG D998 TEST RANGE", "A FLAT LINE")
    path = tmp_path / "flat.kml"
    path.write_text(text.replace(wall, wall + flat, 1))
    with pytest.raises(InputError, match=r"\(A FLAT LINE\): a polygon without area"):
        read_database([path], rules)
