"""The monitor's live source driven by random sequences of good, partial, failed, malformed,
hostile and empty answers from a real server (``tests/hostile_server.py``): after every
answer the zones in force are exactly what the rules say (a model written here, from the
promises: a complete answer sets them, keeping a zone it served malformed; a first empty
answer is not believed; anything else only adds), so never fewer than the last complete
answer's; and the polling loop is alive at the end. A source that trusts a partial answer
breaks the property, and the test sees it."""

from __future__ import annotations

import asyncio
import contextlib

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from alphafence.fencing.pipeline import BuildOptions
from alphafence.monitor.live import LiveOptions, LiveSource
from alphafence.monitor.live_parts import pool
from alphafence.monitor.live_zones import LiveZones
from alphafence.zones.rules import load_rules
from tests.hostile_server import HostileServer
from tests.live_servers import ed318_zone
from tests.test_hostile_source import options, take
from tests.test_live_monitor import Companion, square

NAMES = ("A", "B", "C", "D")
FAILED = ("html", "deep-body", "redirect-other-port", "not-modified-unasked", "reset")
INCOMPLETE_FIRST = ("partial", "next-self", "returned-more")  # the first zone read, then stop
KINDS = ("good", "good", "empty", "nan-vertex", "matched-fewer", "date-9999",
         *FAILED, *INCOMPLETE_FIRST)  # fmt: skip
ZONES = {n: ed318_zone(n, square(14.51 + 0.01 * k, 35.91)) for k, n in enumerate(NAMES)}

answers = st.lists(
    st.tuples(st.sampled_from(KINDS), st.frozensets(st.sampled_from(NAMES), max_size=4)),
    min_size=1,
    max_size=7,
)


WORKER = []  # the module's one fencing worker, for every example (a spawn costs a CPU second)


class SharedWorker(LiveSource):
    """The monitor's polling as it is, its worker process the module's."""

    @contextlib.asynccontextmanager
    async def opened(self):
        from alphafence.sources.ogc import session

        self.pool, self._http = WORKER[0], session(self.options.source)
        try:
            yield self
        finally:
            await self._http.close()


class Model:
    """What must be in force after each answer, from the promises alone."""

    def __init__(self):
        self.in_force, self.empty_pending = set(), False

    def take(self, kind, served):
        served = sorted(served)
        if kind in FAILED:
            return
        if kind in INCOMPLETE_FIRST:
            self.in_force |= set(served[:1])
            return
        if kind == "matched-fewer" and served:  # every page read, the count wrong: incomplete
            self.in_force |= set(served)
            return
        if kind == "matched-fewer":  # nothing served, nothing matched: a complete empty answer
            kind = "empty"
        held = set()
        if kind == "empty":
            served = []
        if kind == "nan-vertex" and served:
            if len(served) == 1:
                return  # every feature malformed: a failed answer
            held, served = {served[0]}, served[1:]
        if not served:
            if self.in_force and not self.empty_pending:
                self.empty_pending = True
                return
            self.empty_pending, self.in_force = False, set()
            return
        self.empty_pending = False
        self.in_force = set(served) | (held & self.in_force)


async def flown(sequence, server, live_class=SharedWorker):
    """Every answer of ``sequence`` taken by a polling loop; the model checked after each."""
    companion = Companion()
    o = LiveOptions(options(server.collection, None, limit=1), load_rules(), BuildOptions(),
                    refresh_s=3600.0, stale_after_s=3600.0)  # fmt: skip
    live = live_class(companion, o, companion.engine.fences.records)
    model, stop = Model(), asyncio.Event()
    server.zones, server.case = [], None
    first = asyncio.ensure_future(live.next_refresh())
    task = asyncio.create_task(live.run(stop))
    try:
        await first
        for kind, served in sequence:
            server.zones = [ZONES[n] for n in sorted(served)]
            await take(live, None if kind == "good" else kind, server)
            model.take(kind, served)
            assert companion.in_force() == model.in_force, (kind, sorted(served), sequence)
            assert not task.done(), "the polling ended"
    finally:
        stop.set()
        live.hint()
        await task


@pytest.fixture(scope="module")
def server():
    WORKER.append(pool())
    try:
        with HostileServer() as other, HostileServer(other=other.url) as s:
            yield s
    finally:
        WORKER.pop().shutdown(wait=True, cancel_futures=True)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(answers)
@example([("good", frozenset("A")), ("good", frozenset()), ("matched-fewer", frozenset())])
def test_the_zones_in_force_follow_the_promises_for_any_answers(server, sequence):
    asyncio.run(flown(sequence, server))


class Trusting(LiveZones):
    """Broken on purpose: every answer taken as complete."""

    def answer(self, zones, complete, bbox=None, held=()):
        return super().answer(zones, True, bbox, held)


class Forgetting(LiveZones):
    """Broken on purpose: a zone served malformed is not held (it was lifted so)."""

    def answer(self, zones, complete, bbox=None, held=()):
        return super().answer(zones, complete, bbox, ())


def broken(rule):
    class Broken(SharedWorker):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            self.zones = rule()

    return Broken


@pytest.mark.parametrize(
    "rule, second",
    [(Trusting, "partial"), (Forgetting, "nan-vertex")],
    ids=["trusts-partial-answers", "lifts-malformed-zones"],
)
def test_a_broken_rule_is_caught(server, rule, second):
    sequence = [("good", frozenset("AB")), (second, frozenset("AB"))]
    asyncio.run(flown(sequence, server))
    with pytest.raises(AssertionError, match=second):
        asyncio.run(flown(sequence, server, broken(rule)))
