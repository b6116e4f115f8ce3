"""ED-269 (and ED-318) files written the way InterUSS, EUROCAE and authorities write them:
feet, the UASZoneList wrapper, numbers given as strings, the successor format, and zones that
must never share one fence (time windows, restriction, altitude band, reference)."""

import json
from pathlib import Path

import pytest
import shapely

from alphafence.formats.database import read_database
from alphafence.geo.frame import LocalFrame

DATA = Path(__file__).parent / "data" / "ed269"


def load(name):
    return json.loads((DATA / name).read_text())


def local_radius(feature, lon, lat):
    """The largest distance (m) from (lon, lat) to the feature's outline."""
    local = LocalFrame(lon, lat).geom_to_local(feature.geometry)
    return shapely.hausdorff_distance(local, shapely.Point(0, 0))


# -- 2: a circle's radius in feet ------------------------------------------------------


def test_a_circle_radius_in_feet_is_converted(rules):
    (zone,) = read_database([DATA / "feet-circle.json"], rules).features
    assert zone.alt_min_m == 0 and zone.alt_max_m == pytest.approx(400 * 0.3048)
    # 1000 ft is 304.8 m: the polygon circumscribes that circle, not a 1000 m one
    r = local_radius(zone, 8.5421, 47.3769)
    assert 304.8 <= r < 304.8 * 1.01
    local = LocalFrame(8.5421, 47.3769).geom_to_local(zone.geometry)
    assert local.covers(shapely.Point(0, 0).buffer(304.79, quad_segs=64))
    assert zone.properties["circle"] == [8.5421, 47.3769, pytest.approx(304.8)]
