"""Which of a live source's zones are in force: for any sequence of answers (adds, changes,
removals, failures, partial pages, areas, empty answers), the zones in force hold every zone
of the last complete answer, and a zone leaves only by a complete answer for an area its
geometry meets that no longer holds it (an empty one, only when the one before it was empty
too). A rule that trusts incomplete answers breaks the property, and the test sees it."""

from __future__ import annotations

from dataclasses import dataclass

import shapely
from hypothesis import given
from hypothesis import strategies as st

from alphafence.monitor.live_zones import LiveZones, zone_meets
from alphafence.sources.answers import Zone

WEST, EAST = (14.0, 35.0, 14.5, 35.5), (14.5, 35.0, 15.0, 35.5)
AREAS = [WEST, EAST, (14.0, 35.0, 15.0, 35.5), None]


@dataclass(frozen=True)
class Restricted:
    geometry: object


def zone(ident: int, version: int) -> Zone:
    lon = 14.1 + 0.09 * ident  # ids 0-4 west, 5-9 east
    box = shapely.box(lon, 35.2, lon + 0.01, 35.21)
    return Zone(f"Z{ident}", f"h{ident}.{version}", {"id": f"Z{ident}"}, (Restricted(box),))


answers = st.lists(
    st.tuples(
        st.frozensets(st.tuples(st.integers(0, 9), st.integers(0, 2)), max_size=6),
        st.sampled_from(["complete", "partial", "failed"]),
        st.sampled_from(AREAS),
        st.frozensets(st.integers(0, 9), max_size=3),  # ids served malformed
    ),
    max_size=12,
)


def run_and_check(states, sequence):
    """Feed ``sequence`` to ``states`` and check the property after every answer."""
    last_complete = None
    previous_empty = False
    for served, outcome, area, *malformed in sequence:
        if outcome == "failed":
            continue  # a failed answer never reaches the zone set
        served = {i: v for i, v in sorted(served)}  # one version per id in an answer
        held = {f"Z{i}" for i in (malformed[0] if malformed else ()) if i not in served}
        zones = [zone(i, v) for i, v in served.items()]
        before = set(states.versions)
        states.answer(zones, outcome == "complete", area, held)
        after = set(states.versions)
        keys = {(z.id, z.hash) for z in zones}
        assert keys <= after, "a served zone is not in force"
        for key in before - after:
            gone = zone(int(key[0][1:]), int(key[1].split(".")[1]))
            assert outcome == "complete", f"{key} removed by a {outcome} answer"
            assert zone_meets(gone, area), f"{key} removed by an answer for another area"
            assert key not in keys
            assert key[0] not in held, f"{key} removed by an answer that served it malformed"
            assert zones or previous_empty, f"{key} removed by a first empty answer"
        if outcome == "complete":
            last_complete = keys
            previous_empty = not zones and bool(before - keys)
        if last_complete is not None:
            assert last_complete <= after, "fewer zones than the last complete answer"


@given(answers)
def test_zones_in_force_never_fewer_than_the_last_complete_answer(sequence):
    run_and_check(LiveZones(), sequence)


class TrustsPartialAnswers(LiveZones):
    """Broken on purpose: takes every answer as complete."""

    def answer(self, zones, complete, bbox=None, held=()):
        return super().answer(zones, True, bbox, held)


class LiftsMalformedZones(LiveZones):
    """Broken on purpose: a zone served malformed counts as absent."""

    def answer(self, zones, complete, bbox=None, held=()):
        return super().answer(zones, complete, bbox, ())


def test_a_rule_that_lifts_malformed_zones_is_caught():
    sequence = [
        (frozenset({(1, 0), (2, 0)}), "complete", WEST, frozenset()),
        (frozenset({(1, 0)}), "complete", WEST, frozenset({2})),  # zone 2 served with a NaN
    ]
    run_and_check(LiveZones(), sequence)
    try:
        run_and_check(LiftsMalformedZones(), sequence)
    except AssertionError as exc:
        assert "served it malformed" in str(exc)
    else:
        raise AssertionError("the broken rule passed")


def test_a_rule_that_trusts_partial_answers_is_caught():
    sequence = [
        (frozenset({(1, 0), (2, 0)}), "complete", WEST),
        (frozenset({(1, 0)}), "partial", WEST),  # page 2 failed: zone 2 was on it
    ]
    run_and_check(LiveZones(), sequence)
    try:
        run_and_check(TrustsPartialAnswers(), sequence)
    except AssertionError as exc:
        assert "removed by a partial answer" in str(exc)
    else:
        raise AssertionError("the broken rule passed")


def test_an_empty_answer_needs_a_second_to_remove_and_other_areas_keep_theirs():
    states = LiveZones()
    states.answer([zone(1, 0), zone(7, 0)], True, None)
    change = states.answer([], True, WEST)
    assert not change and [z.id for z in change.kept_empty] == ["Z1"]
    assert {z.id for z in states.zones} == {"Z1", "Z7"}
    change = states.answer([], True, WEST)
    assert [z.id for z in change.removed] == ["Z1"] and [z.id for z in states.zones] == ["Z7"]
    change = states.answer([zone(7, 1)], False, EAST)  # a new version: both until complete
    assert [z.hash for z in change.changed] == ["h7.1"] and len(states.zones) == 2
    change = states.answer([zone(7, 1)], True, EAST)
    assert not change.removed and [z.hash for z in states.zones] == ["h7.1"]


def test_each_answer_says_what_it_changed_and_counts_in_the_revision():
    live = LiveZones()
    assert live.revision == 0 and not live.empty_pending
    first = live.answer([zone(1, 0), zone(6, 0)], True)
    assert ([z.id for z in first.added], first.changed, first.removed) == (["Z1", "Z6"], [], [])
    assert first and live.revision == 1
    again = live.answer([zone(1, 0), zone(6, 0)], True)
    assert not again and live.revision == 1  # nothing changed: no revision
    moved = live.answer([zone(1, 1), zone(6, 0)], True)  # a new version of Z1 only
    assert [z.hash for z in moved.changed] == ["h1.1"] and not moved.added and moved
    assert live.revision == 2
    held = live.answer([zone(6, 0)], True, held=["Z1"])  # Z1 served malformed: kept
    assert sorted(z.hash for z in held.held) == ["h1.1"] and not held.removed and not held
    assert live.revision == 2
    gone = live.answer([zone(1, 1)], True)  # Z6 no longer served
    assert [z.id for z in gone.removed] == ["Z6"] and gone and live.revision == 3
    assert sorted(z.hash for z in live.zones) == ["h1.1"]


def test_a_zone_meets_an_area_by_its_restricted_features_else_its_own_geometry():
    west_box = {"type": "Polygon", "coordinates": [[[14.1, 35.2], [14.2, 35.2], [14.2, 35.3],
                                                    [14.1, 35.2]]]}  # fmt: skip
    bare = Zone("B", "h", {"id": "B", "geometry": west_box}, ())
    assert zone_meets(bare, WEST) and not zone_meets(bare, EAST)
    # restricted features (fenced) decide over the feature's own geometry
    east = Restricted(shapely.box(14.8, 35.2, 14.81, 35.21))
    both = Zone("C", "h", {"id": "C", "geometry": west_box}, (east,))
    assert zone_meets(both, EAST) and not zone_meets(both, WEST)
    # a geometry GEOS cannot read meets every area (it is never taken away by one)
    broken = Zone(
        "D", "h", {"id": "D", "geometry": {"type": "Polygon", "coordinates": [[[1]]]}}, ()
    )
    assert zone_meets(broken, WEST) and zone_meets(broken, EAST)
    assert zone_meets(bare, None)
