"""The monitor's CPU on SITL, per vehicle link, at 10 and 50 Hz telemetry, against the floor.

Runs the real monitor (link, telemetry tasks, checker, log writer) against one SITL at speedup
1 over the Malta fences, with position and velocity asked for at each rate, on each link that
is installed (``pymavlink``: the pure-Python link; ``mavsdk``: MAVSDK 4's native binding, the
named peer), and measures this process's CPU time (all its threads, MAVSDK's included) against
wall time and against the positions the monitor checked: the CPU per position. Each figure is
the least of several windows (:mod:`bench.monitor_probe`, which measures it, is also what
`make navio2-test` runs under qemu).

The floor: right after the pymavlink monitor stops, an asyncio UDP endpoint that does nothing
binds the same port and receives the same datagrams (SITL keeps sending the streams at the
rates the monitor asked for), measured the same way. Targets: the link the kit chooses at
50 Hz costs at most :data:`FLOOR_RATIO` times the floor, and under :data:`TARGETS` of a core.
"""

from __future__ import annotations

import asyncio

from alphafence.sitl.find import find_sitl_binary
from bench import cold_bench
from bench.monitor_probe import measure_floor, measure_monitor, port_of

RATES = (10.0, 50.0)
TARGETS = {10.0: 0.004, 50.0: 0.02}  # of one core, for the link the kit chooses
FLOOR_RATIO = {50.0: 1.3}  # the chosen link's monitor against the floor


def malta_fences(osm):
    """The fences built from ``osm`` as the monitor loads them (with names, as a map shows)."""
    from alphafence.awareness.fenceset import FenceSet
    from alphafence.fencefiles.fence_geojson import FenceRecord
    from alphafence.fencing.pipeline import BuildOptions, build_fences
    from alphafence.zones.database import read_database
    from alphafence.zones.rules import load_rules

    rules = load_rules()
    result = build_fences(read_database([osm], rules).features, rules, BuildOptions())
    return FenceSet(
        [
            FenceRecord(f.site_id, f.kind, f.geometry, f.margin_m, name=f.name, category=f.category)
            for f in result.fences
        ]
    )


async def _measure(fences, links):
    from alphafence.sitl import launch_sitl

    out = {}
    async with launch_sitl(home="malta_airport", speedup=1) as sitl:
        for link in links:
            for hz in RATES:
                out[link, hz] = await measure_monitor(sitl.connection_url, fences, link, hz)
                if link == "pymavlink":
                    out["floor", hz] = await measure_floor(port_of(sitl.connection_url))
    return out, len(fences.records)


def run(osm, Row):
    from alphafence.vehicle.link import LINKS, NoLinkError, choose_link

    if find_sitl_binary() is None:
        return [Row("monitor CPU per link", "skipped: no SITL binary", "-", "-", "-", True)]
    links = []
    for link in LINKS[1:]:
        try:
            links.append(choose_link(link))
        except NoLinkError:
            pass
    chosen = choose_link("auto")
    fences = malta_fences(osm)
    got, n = asyncio.run(_measure(fences, links))
    rows = cold_bench.run(fences, Row)
    for hz in RATES:
        floor = got.get(("floor", hz))
        if floor is not None:
            share, rate, per = floor
            rows.append(
                Row(
                    f"floor: a UDP endpoint doing nothing with SITL's datagrams, {hz:g} Hz streams",
                    f"{100 * share:.2f} % of a core, {rate:.0f} datagrams/s",
                    "-", "-", "-", True, value=100 * share, unit="% of a core",
                )
            )  # fmt: skip
        if floor is not None and chosen == "pymavlink" and hz in FLOOR_RATIO:
            share = got["pymavlink", hz][0]
            ratio = share / max(floor[0], 1e-9)
            rows.append(
                Row(
                    f"monitor CPU against the floor, pymavlink link (auto), {hz:g} Hz",
                    f"{100 * share:.2f} % against {100 * floor[0]:.2f} %",
                    f"<= {FLOOR_RATIO[hz]:g}x the floor",
                    f"floor {100 * floor[0]:.2f} %",
                    f"{ratio:.2f}x",
                    ratio <= FLOOR_RATIO[hz],
                    value=ratio,
                    unit="x the floor",
                    peer_value=100 * floor[0],
                )
            )
        peer = got.get(("mavsdk", hz))
        for link in links:
            share, rate, per = got[link, hz]
            is_peer = link == "mavsdk"
            rows.append(
                Row(
                    f"monitor CPU on SITL, {link} link{' (auto)' if link == chosen else ''}, "
                    f"{hz:g} Hz, {n} Malta fences",
                    f"{100 * share:.2f} % of a core, {1e6 * per:.0f} us/position, "
                    f"{rate:.0f} checks/s",
                    f"< {100 * TARGETS[hz]:g} %" if link == chosen else "-",
                    "-" if is_peer or peer is None else f"mavsdk {100 * peer[0]:.2f} %",
                    "-" if is_peer or peer is None else f"{share / peer[0]:.2f}x",
                    (link != chosen or share < TARGETS[hz]) and rate >= 0.8 * hz,
                    value=100 * share,
                    unit="% of a core",
                    peer_value=None if is_peer or peer is None else 100 * peer[0],
                )
            )
    return rows
