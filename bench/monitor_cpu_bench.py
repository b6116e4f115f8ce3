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
# the chosen link's monitor against the floor: far from fences, and near them (no worse than
# before the lazy check)
FLOOR_RATIO = {("far", 10.0): 1.3, ("far", 50.0): 1.5, ("near", 10.0): 3.0, ("near", 50.0): 2.5}


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


# where the copter sits: SITL's Malta home, 230 m from the airport's keep-out (a full check
# every second or so), and 3.7 km off Malta's south-east coast (one every ten seconds or so)
NEAR = "malta_airport"
FAR = dict(name="malta_offshore", lat=35.82, lon=14.60, alt=0.0, heading=0.0)
PLACES = {"near": "230 m from the nearest fence", "far": "3.7 km from the nearest fence"}


async def _measure(fences, links):
    from alphafence.sitl import launch_sitl
    from alphafence.sitl.homes import Home

    out = {}
    for place, home in (("near", NEAR), ("far", Home(**FAR, description=PLACES["far"]))):
        async with launch_sitl(home=home, speedup=1) as sitl:
            for link in links if place == "near" else ["pymavlink"]:
                for hz in RATES:
                    url = sitl.connection_url
                    out[place, link, hz] = await measure_monitor(url, fences, link, hz)
                    if link == "pymavlink":
                        out[place, "floor", hz] = await measure_floor(port_of(url))
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
    for place, hz in ((p, hz) for p in ("far", "near") for hz in RATES):
        where = f"{hz:g} Hz, {PLACES[place]}"
        floor = got[place, "floor", hz]
        rows.append(
            Row(
                f"floor: a UDP endpoint doing nothing with SITL's datagrams, {where}",
                f"{100 * floor[0]:.2f} % of a core, {floor[1]:.0f} datagrams/s",
                "-", "-", "-", True, value=100 * floor[0], unit="% of a core",
            )
        )  # fmt: skip
        share, rate, per, full = got[place, "pymavlink", hz]
        if chosen == "pymavlink":
            ratio = share / max(floor[0], 1e-9)
            target = FLOOR_RATIO[place, hz]
            rows.append(
                Row(
                    f"monitor CPU against the floor, pymavlink link (auto), {where}",
                    f"{100 * share:.2f} % against {100 * floor[0]:.2f} %, "
                    f"{100 * full:.1f} % of positions checked in full",
                    f"<= {target:g}x the floor",
                    f"floor {100 * floor[0]:.2f} %",
                    f"{ratio:.2f}x",
                    ratio <= target,
                    value=ratio,
                    unit="x the floor",
                    peer_value=100 * floor[0],
                )
            )
        peer = got.get((place, "mavsdk", hz))
        for link in links if place == "near" else ["pymavlink"]:
            share, rate, per, full = got[place, link, hz]
            is_peer = link == "mavsdk"
            rows.append(
                Row(
                    f"monitor CPU on SITL, {link} link{' (auto)' if link == chosen else ''}, "
                    f"{where}, {n} Malta fences",
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
