"""How many inclusions a fence holds (``alphafence.mavlink.inclusions``), against the fence's
own making: random runs of inclusion and exclusion polygons (each vertex item carrying the
polygon's vertex count, as MAVLink's fence protocol has it), inclusion and exclusion circles
and return points, in any order. ArduPilot reads two or more inclusions as their
intersection unless FENCE_OPTIONS bit 1 (value 2) is set."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from alphafence.mavlink.inclusions import (
    inclusion_count,
    needs_union,
    options_with_union,
    union_note,
    union_of,
)
from alphafence.mavlink.items import FenceItem

# MAVLink's common.xml
POLYGON_INCLUSION, POLYGON_EXCLUSION, CIRCLE_INCLUSION, CIRCLE_EXCLUSION = 5001, 5002, 5003, 5004
RETURN_POINT = 5000

shapes = st.lists(
    st.one_of(
        st.tuples(st.sampled_from(["polygon in", "polygon out"]), st.integers(3, 9)),
        st.tuples(st.sampled_from(["circle in", "circle out", "return"]), st.just(0)),
    ),
    max_size=8,
)


def items_of(parts):
    items = []
    for kind, n in parts:
        if kind.startswith("polygon"):
            command = POLYGON_INCLUSION if kind.endswith("in") else POLYGON_EXCLUSION
            items += [FenceItem(command, float(n), 14.5 + k * 1e-3, 35.9) for k in range(n)]
        elif kind == "return":
            items.append(FenceItem(RETURN_POINT, 0.0, 14.5, 35.9))
        else:
            command = CIRCLE_INCLUSION if kind.endswith("in") else CIRCLE_EXCLUSION
            items.append(FenceItem(command, 50.0, 14.5, 35.9))
    return items


@settings(max_examples=300, deadline=None)
@given(shapes)
def test_inclusions_are_counted_as_the_fence_was_made(parts):
    items = items_of(parts)
    want = sum(kind in ("polygon in", "circle in") for kind, _ in parts)
    assert inclusion_count(items) == want
    assert needs_union(items) is (want > 1)
    note = union_note(items)
    if want < 2:
        assert note is None
    else:
        assert note == (
            f"{want} inclusion areas: ArduPilot needs FENCE_OPTIONS bit 1 (value 2: union of "
            "inclusion areas) to read them as meant, else it reads their intersection "
            "(alphafence upload sets it; with another tool, set it there)"
        )


def test_the_union_bit_is_set_and_read_keeping_the_other_bits():
    assert [options_with_union(v) for v in (None, 0, 1, 2, 4, 7.0)] == [2, 2, 3, 2, 6, 7]
    assert [union_of(v) for v in (None, 0, 1, 2, 3, 4, 6.0)] == [
        False, False, False, True, True, False, True,
    ]  # fmt: skip


def test_a_count_that_ignores_polygon_runs_is_caught():
    # broken on purpose: counting vertex items instead of polygons says 4 for one square
    square = items_of([("polygon in", 4)])
    assert sum(it.command == POLYGON_INCLUSION for it in square) == 4 != inclusion_count(square)
