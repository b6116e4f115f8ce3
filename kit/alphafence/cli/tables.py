"""Tables more than one verb prints: the method comparison (``compare``, ``demo``) and the
onboard fence (``compile``, ``upload``)."""

from __future__ import annotations

import argparse

from rich.table import Table

from alphafence.cli.common import err_console, out_console


def stats_table(cmp, opts) -> Table:
    """The comparison of fence methods, one row per method.

    Parameters
    ----------
    cmp : alphafence.fencing.compare.Comparison
        What :func:`alphafence.fencing.compare.compare_methods` returned.
    opts : alphafence.fencing.pipeline.BuildOptions
        The options it ran with (the title names the margin).
    """
    margin = "rules' margins" if opts.margin_m is None else f"margin {opts.margin_m:g} m"
    t = Table(title=f"{cmp.stats[0].sites} sites, {margin}")
    for col in (
        "method",
        "contain %",
        "overshoot",
        "excess",
        "v median",
        "v p95",
        "v total",
        "time s",
    ):
        t.add_column(col, justify="left" if col == "method" else "right")
    for s in cmp.stats:
        t.add_row(
            s.method,
            f"{s.containment_pct:.2f}",
            f"{s.overshoot:.3f}",
            f"{s.excess:.3f}",
            f"{s.vertices_median:.0f}",
            f"{s.vertices_p95:.0f}",
            str(s.vertices_total),
            f"{s.seconds:.2f}",
        )
    return t


def corridor_line(result) -> str:
    """One line on the onboard fence's overshoot within the corridor of a compilation.

    Parameters
    ----------
    result : alphafence.onboard.compile.CompileResult

    Returns
    -------
    str
        Empty when the compilation has no corridor.
    """
    c, o = result.corridor, result.overshoot
    if c is None or o is None:
        return ""
    where = "the flight path" if c.of_path else "the area"
    size = f"{c.area.area / 1e6:.2f} km²" if not c.area.is_empty else "no area"
    if o.fenced_m2 <= 0:
        return f"corridor within {c.distance_m:g} m of {where} ({size}): no fence in it"
    return (
        f"corridor within {c.distance_m:g} m of {where} ({size}): the onboard fence forbids "
        f"{o.added_m2 / 1e4:.2f} ha there that the full-resolution fences allow, "
        f"overshoot {o.ratio:.3f} of their {o.fenced_m2 / 1e4:.2f} ha"
    )


def compile_report(result) -> None:
    """Print what a compilation stored, piece by piece (each by its sites' ids and names),
    its overshoot within the corridor, and notes on what it left out or merged.

    Parameters
    ----------
    result : alphafence.onboard.compile.CompileResult
    """
    bytewise = result.profile.autopilot == "ardupilot"  # PX4 counts items, not bytes
    size = (f"{len(result.items)} items, {result.bytes_used} of {result.profile.bytes} bytes"
            if bytewise else f"{len(result.items)} of {result.profile.items} items")  # fmt: skip
    t = Table(
        title=f"{size} ({result.profile.name}); area added in the corridor "
        f"{result.loss_m2 / 1e4:.2f} ha",
    )
    cols = ("fence(s)", "kind", "stored as", "items", "bytes", "lost in corridor m²")
    for col in cols if bytewise else [c for c in cols if c != "bytes"]:
        t.add_column(col, justify="left" if col in ("fence(s)", "kind", "stored as") else "right")
    for p in result.pieces:
        o = p.chosen
        full = len(p.local.exterior.coords) - 1
        label = ", ".join(result.label(site) for site in p.sources[:3]) + (
            f" (+{len(p.sources) - 3})" if len(p.sources) > 3 else ""
        )
        how = (
            o.label
            + (" (merged)" if p.merged else "")
            + (f" of {full}" if o.kind == "polygon" and o.items < full else "")
        )
        row = [label, "keep-in" if p.inclusion else "keep-out", how, str(o.items)]
        t.add_row(*row, *([str(o.bytes)] if bytewise else []), f"{o.loss:.0f}")
    out_console.print(t)
    if corridor_line(result):
        out_console.print(corridor_line(result), highlight=False)
    if result.dropped:
        err_console.print(
            f"[yellow]note:[/] {len(result.dropped)} fence(s) farther than the selection distance were left out"
        )
    for m in result.merges:
        named = ", ".join(result.label(site) for site in m)
        err_console.print(f"[yellow]note:[/] merged {named} to fit the storage", soft_wrap=True)


def items_report(items, fences, profile, sites=None) -> None:
    """Print the items an upload sends: one row per polygon or circle (with the sites it
    stands for, ``sites[k]`` for ``fences[k]``, when the plan says), and the return point."""
    from alphafence.mavlink.items import RETURN_POINT
    from alphafence.mavlink.storage import CIRCLE_BYTES, RETURN_BYTES, polygon_bytes, storage_bytes

    if profile.autopilot == "ardupilot":
        size = f"{len(items)} items, {storage_bytes(items)} of {profile.bytes} bytes "
    else:  # PX4 counts items only (the bytes column is what ArduPilot would take)
        size = f"{len(items)} items "
    t = Table(title=f"{size}({profile.name}), at most {profile.items} items")
    cols = ("sent as", "fence", "stands for", "size", "bytes", "first position (lat, lon)")
    for col in cols:
        t.add_column(col, justify="right" if col == "bytes" else "left")
    for k, it in enumerate(items):
        if it.command == RETURN_POINT:
            pos = f"{it.lat:.7f}, {it.lon:.7f}"
            t.add_row(f"item {k}", "return point", "", "", str(RETURN_BYTES), pos)
    sites = list(sites or []) + [[]] * len(fences)
    for f, stands_for in zip(fences, sites):
        lon, lat = f.lonlat[0]
        polygon = f.shape == "polygon"
        t.add_row(
            f.items,
            f"{f.kind} {f.shape} {f.number}",
            ", ".join(_site(x) for x in stands_for),
            f"{len(f.lonlat)} vertices" if polygon else f"radius {f.radius_m:g} m",
            str(polygon_bytes(len(f.lonlat)) if polygon else CIRCLE_BYTES),
            f"{lat:.7f}, {lon:.7f}",
        )
    out_console.print(t)


def _site(site) -> str:
    """A site as tables name it: ``hospital/way/1 (St Mary's)``, or its id alone."""
    return f"{site['id']} ({site['name']})" if site.get("name") else site["id"]


class Presets(argparse.Action):
    """``--params``: a preset's name, or ``list`` (print every preset's parameters, exit 0)."""

    def __call__(self, parser, namespace, values, option_string=None):
        if values != "list":
            setattr(namespace, self.dest, values)
            return
        from alphafence.mavlink.inclusions import UNION_WORDS
        from alphafence.vehicle.params import VEHICLE, describe

        t = Table(title="--params presets (ArduPilot's AC_Fence, PX4's geofence parameters)")
        for col in ("preset", "vehicle", "parameters set"):
            t.add_column(col)
        for name, vehicle in VEHICLE.items():
            t.add_row(name, vehicle, describe(name))
        t.caption = (
            f"A fence of two or more inclusion areas also gets {UNION_WORDS}, whatever the "
            "preset, on ArduPilot 4.5 and later; older firmware gets them as one inclusion and "
            "an exclusion per gap"
        )
        out_console.print(t)
        parser.exit(0)


def gaps_report(compiled, rule) -> None:
    """Say when several keep-in areas were compiled as one inclusion and its gaps, and why."""
    from alphafence.onboard.gaps import GAP_ID

    gaps = sum(p.sources[0].startswith(GAP_ID) for p in compiled.pieces if p.sources)
    if gaps:
        from alphafence.mavlink.autopilots import NAMES

        name = NAMES[compiled.profile.autopilot]
        why = rule[2] if rule else f"{name} reads several inclusions as their intersection"
        out_console.print(f"keep-in areas compiled as one inclusion round them and {gaps} gap "
                          f"exclusion{'s' * (gaps > 1)}: {why}", soft_wrap=True)  # fmt: skip
