"""ED-269 applicability: time-windowed fences switch on and off."""

from datetime import datetime, timezone

import pytest
import shapely

from alphafence.awareness.applicability import is_active, timed
from alphafence.awareness.fenceset import FenceSet
from alphafence.fencefiles.fence_geojson import FenceRecord
from alphafence.geo.frame import LocalFrame

UTC = timezone.utc
WEEKDAYS_9_TO_17 = [
    {
        "permanent": "NO",
        "startDateTime": "2026-11-01T00:00:00Z",
        "endDateTime": "2026-12-01T00:00:00Z",
        "schedule": [
            {
                "day": ["MON", "TUE", "WED", "THU", "FRI"],
                "startTime": "09:00:00Z",
                "endTime": "17:00:00Z",
            }
        ],
    }
]


@pytest.mark.parametrize(
    "when, active",
    [
        (datetime(2026, 11, 23, 10, 0, tzinfo=UTC), True),  # Monday 10:00
        (datetime(2026, 11, 23, 18, 0, tzinfo=UTC), False),  # Monday evening
        (datetime(2026, 11, 22, 10, 0, tzinfo=UTC), False),  # Sunday
        (datetime(2026, 12, 2, 10, 0, tzinfo=UTC), False),  # after the end date
    ],
)
def test_schedule(when, active):
    assert is_active(WEEKDAYS_9_TO_17, when) is active


def test_permanent_missing_or_unreadable_means_in_force():
    now = datetime(2026, 11, 22, tzinfo=UTC)
    assert (
        is_active(None, now) and is_active([{"permanent": "YES"}], now) and is_active(["junk"], now)
    )
    assert not timed(None) and not timed([{"permanent": "YES"}]) and timed(WEEKDAYS_9_TO_17)


def test_fenceset_ignores_a_zone_out_of_hours():
    frame = LocalFrame(-0.55, 51.43)
    zone = FenceRecord(
        "zone/1",
        "keep_out",
        frame.geom_to_wgs84(shapely.box(-50, -50, 50, 50)),
        properties={"zone": {"applicability": WEEKDAYS_9_TO_17}},
    )
    far = FenceRecord("far", "keep_out", frame.geom_to_wgs84(shapely.box(1000, 0, 1100, 100)))
    fs = FenceSet([zone, far], frame=frame)
    fs.set_time(datetime(2026, 11, 23, 10, 0, tzinfo=UTC))
    during = fs.check(0, 0, 20.0)
    assert during.inside_keep_out == [0] and during.nearest_keep_out.index == 0
    ahead = fs.check(0, -200, 20.0, 0.0, 10.0, 500.0)
    assert ahead.breach_ahead[0] == 0 and ahead.breach_ahead[1] == pytest.approx(150, abs=0.01)
    fs.set_time(datetime(2026, 11, 23, 20, 0, tzinfo=UTC))
    after = fs.check(0, 0, 20.0)
    assert after.inside_keep_out == [] and after.nearest_keep_out.index == 1
    assert fs.check(0, -200, 20.0, 0.0, 10.0, 500.0).breach_ahead is None
