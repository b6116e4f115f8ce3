"""alphafence check-flight: did a logged flight enter a restricted zone? Every position of a
telemetry log (.tlog) or DataFlash log (.BIN) through the monitor's fence engine, at the log's
own times."""

from __future__ import annotations

import json
import sys

from rich.table import Table

from alphafence.cli.common import out_console
from alphafence.cli.maps import add_map_options, check_map_args
from alphafence.cli.options import figure_wants, positive

SHOWN = 20  # fences listed in the table (--json lists every one)


def register(sub):
    """Add the ``check-flight`` verb to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "check-flight",
        help="check a flight log against fences: did it enter a restricted zone?",
        description="Read a telemetry log (.tlog: GLOBAL_POSITION_INT at the log's "
        "timestamps) or an ArduPilot DataFlash log (.BIN: POS, or GPS; UTC from GPS time) and "
        "run every position through the monitor's fence engine at the time it was flown: "
        "time windows in force then, altitude limits with the log's altitude (AMSL limits "
        "with the altitude AMSL, AGL ones with the height above home). Lists the fences "
        "entered (keep-in fences left) with when, where and how deep, the lines between "
        "positions that cross a fence no position is in, the closest approach to every fence "
        "within --near, and the alerts the monitor would have raised. Exit code 1 when the "
        "flight entered a keep-out fence in force or left a keep-in fence, 2 on a bad log or "
        "bad fences (nothing written), else 0.",
    )
    p.add_argument("log", metavar="LOG", help="telemetry log (.tlog) or DataFlash log (.BIN)")
    p.add_argument("--fences", required=True, metavar="FENCES", help="fence file (any format)")
    p.add_argument(
        "--near",
        type=positive("--near", "metres"),
        default=500.0,
        metavar="M",
        help="closest approaches to the fences within M metres of the track (default 500)",
    )
    p.add_argument(
        "--sysid",
        type=int,
        metavar="N",
        help="the vehicle's MAVLink system id in a .tlog (default: the first with a position)",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON to stdout")
    p.add_argument("--figure", metavar="PNG", help="draw the track over the fences")
    add_map_options(p)
    p.set_defaults(func=run)


def _clock(rep, t, date=False):
    if t is None:
        return "-"
    iso = rep.when(t)
    if iso is None:
        return f"T+{t:.1f} s"
    return iso[:23].replace("T", " ") if date else iso[11:23]


def _band(row):
    lo, hi = row["alt_min_m"], row["alt_max_m"]
    if lo is None and hi is None:
        return "any"
    lref, uref = (r or "home" for r in row["references"])
    low = "-" if lo is None else f"{lo:g} {lref}"
    return f"{low} to {'-' if hi is None else f'{hi:g} {uref}'}"


def _incursions(rep):
    t = Table(title="Fences entered (keep-in fences: left)")
    for col in ("fence", "kind", "in", "out", "s", "positions", "depth m", "alt m"):
        t.add_column(col, justify="left" if col in ("fence", "kind", "in", "out") else "right")
    for i in rep.incursions:
        r = rep.fences.records[i.fence]
        kind = {"keep_out": "[red]keep-out[/]", "keep_in": "[red]keep-in (left)[/]"}
        secs = "-" if i.t_out is None else f"{i.t_out - i.t_in:.1f}"
        positions = "between two" if i.between_samples else str(i.samples)
        t.add_row(
            r.site_id + (f" ({r.name})" if r.name else ""),
            kind.get(i.kind, "[yellow]warning layer[/]"),
            _clock(rep, i.t_in),
            "log ends" if i.t_out is None else _clock(rep, i.t_out),
            secs,
            positions,
            f"{i.depth_m:.1f}",
            f"{i.alt_m:.1f}",
        )
    return t


def _fences(rep, rows):
    t = Table(title=f"Fences within {rep.near_m:g} m of the track, closest first")
    for col in ("fence", "kind", "altitudes", "in force", "closest m", "at", "alt m", "entered"):
        t.add_column(col, justify="right" if col in ("closest m", "alt m", "entered") else "left")
    for row in rows[:SHOWN]:
        a = row["closest"] or {}
        t.add_row(
            row["fence"] + (f" ({row['name']})" if row["name"] else ""),
            row["kind"].replace("_", "-"),
            _band(row),
            row["in_force"],
            f"{a['distance_m']:.1f}" if a else "-",
            _clock(rep, a.get("t")),
            f"{a['alt_m']:.1f}" if a else "-",
            str(row["incursions"]) if row["incursions"] else "",
        )
    return t


def _alerts_line(rep):
    counts = {}
    for e in rep.alerts:
        key = e.get("level") or e["event"].replace("_", " ")
        counts.setdefault(key, []).append(e["time"])
    parts = [f"{len(v)} {k} (first {_clock(rep, v[0])})" for k, v in counts.items()]
    return "the monitor would have raised: " + (", ".join(parts) if parts else "no alert")


def _verdict(rep):
    hits = [i for i in rep.incursions if i.kind != "warning"]
    if hits:
        i = hits[0]
        r = rep.fences.records[i.fence]
        what = "LEFT keep-in" if i.kind == "keep_in" else "ENTERED keep-out"
        more = f" (and {len(hits) - 1} more)" if len(hits) > 1 else ""
        return f"[red]{what} fence {r.site_id}[/] at {_clock(rep, i.t_in, True)}{more}"
    keep_out = [
        (a.distance_m, k)
        for k, a in rep.closest.items()
        if rep.fences.records[k].kind == "keep_out" and a.in_force
    ]
    if not keep_out:
        return f"[green]no fence entered[/]; no keep-out fence in force within {rep.near_m:g} m"
    d, k = min(keep_out)
    name = rep.fences.records[k].site_id
    return f"[green]no fence entered[/]; the closest keep-out fence in force: {name}, {d:.1f} m"


def flight_map(args, rep) -> None:
    """Write ``--map``: the fences near the track (grey when never in force), the track by
    height above home, the breaches and the alerts."""
    from alphafence.cli.maps import write_map_page
    from alphafence.plots.webmap import bounds_of, fence_layers
    from alphafence.plots.webmap_layers import fence_indices_near, flight_layers

    if not len(rep.track):
        return
    near = fence_indices_near(rep, max(rep.near_m, 1000.0))
    in_force = {j: rep.in_force[k] for j, k in enumerate(near) if k in rep.in_force}
    records = [rep.fences.records[k] for k in near]
    verdict = "ENTERED a restricted zone" if rep.entered else "no restricted zone entered"
    layers = [*fence_layers(records, in_force=in_force), *flight_layers(rep)]
    bounds = bounds_of(rep.track[:, 1:3])
    write_map_page(args, f"{args.log}: {verdict}", layers, note=f"fences: {args.fences}",
                   bounds=bounds)  # fmt: skip


def run(args) -> int:
    """Check the log against the fences; print the report (or JSON), draw the figure; exit 1
    when the flight entered a keep-out fence in force or left a keep-in fence, else 0."""
    from alphafence.errors import need
    from alphafence.flights.flight_log import FlightLog, log_reader
    from alphafence.review.postflight import check_flight, load_fences

    need((log_reader(args.log), f"reading {args.log}"), *figure_wants(args.figure))
    check_map_args(args)
    fences = load_fences(args.fences)  # first: a map database given for fences is said at once
    log = FlightLog(args.log, sysid=args.sysid)
    rep = check_flight(log, fences, near_m=args.near)
    if args.figure:
        from alphafence.plots.flight_check import flight_check_figure

        flight_check_figure(rep, args.figure, note=f"fences: {args.fences}")
    if args.map:
        flight_map(args, rep)
    if args.json:
        doc = rep.to_json()
        doc["fences_file"] = str(args.fences)
        json.dump(doc, sys.stdout, indent=1, allow_nan=False)
        sys.stdout.write("\n")
        return 1 if rep.entered else 0
    info = rep.info
    who = f", system {info.sysid}" if info.sysid is not None else ""
    span = f"{_clock(rep, rep.start_t, True)} to {_clock(rep, rep.end_t, True)}"
    span += " UTC" if info.clock == "utc" else ""
    out_console.print(
        f"{info.path}: {info.positions} positions ({info.source}{who}), {span}, "
        f"{rep.end_t - rep.start_t:.0f} s"
    )
    if rep.incursions:
        out_console.print(_incursions(rep))
    rows = [r for r in rep.fence_rows() if r["closest"] or r["incursions"]]
    if rows:
        out_console.print(_fences(rep, rows))
        if len(rows) > SHOWN:
            out_console.print(f"... and {len(rows) - SHOWN} more (--json lists every fence)")
    out_console.print(_alerts_line(rep))
    for note in list(info.notes) + rep.notes:
        out_console.print(f"[yellow]note:[/] {note}")
    out_console.print(_verdict(rep))
    for path in (args.figure, args.map):
        if path:
            out_console.print(f"wrote {path}")
    return 1 if rep.entered else 0
