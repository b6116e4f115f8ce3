"""Fences on a map: a build's fences over the restricted features, and the onboard fences a
compile chose over the full-resolution ones."""

from __future__ import annotations

import math

import numpy as np

from alphafence.plots.common import (
    KIND_STYLE,
    draw_polygons,
    draw_restricted,
    save_figure,
    subplots,
)


def fence_map(fences, sites, path, title="AlphaFence fences", note=None):
    """Draw every fence (WGS84) over the restricted features and save it as PNG.

    The aspect ratio is corrected for the latitude, so shapes look as they do on the ground.

    Parameters
    ----------
    fences : list of Fence
        As ``build_fences`` returns them; warning layers are drawn first, keep-out on top.
    sites : list of Site
        Their restricted areas are drawn in grey.
    path : str or Path
        The PNG to write.
    title : str
        The figure's title.
    note : str, optional
        A line of small print at the bottom (e.g. the data's attribution).
    """
    fig, ax = subplots(figsize=(9, 9))
    for s in sites:
        draw_restricted(ax, s.frame.geom_to_wgs84(s.geometry))
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    for f in sorted(fences, key=lambda f: order.get(f.kind, 3)):
        draw_polygons(ax, f.geometry, **KIND_STYLE.get(f.kind, KIND_STYLE["keep_out"]))
    ax.autoscale_view()
    lat = np.mean(ax.get_ylim())
    ax.set_aspect(1.0 / max(math.cos(math.radians(lat)), 0.05), adjustable="datalim")
    ax.set_xlabel("longitude")
    ax.set_ylabel("latitude")
    ax.set_title(title)
    from matplotlib.lines import Line2D

    handles = [
        Line2D(
            [],
            [],
            color=KIND_STYLE[k]["edgecolor"],
            ls=KIND_STYLE[k].get("ls", "-"),
            label=k.replace("_", "-"),
        )
        for k in ("keep_out", "warning", "keep_in")
        if any(f.kind == k for f in fences)
    ]
    handles.append(Line2D([], [], color="#9e9e9e", lw=6, label="restricted area"))
    ax.legend(handles=handles, loc="upper right", fontsize=8)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    save_figure(fig, path)


def onboard_figure(records, result, path):
    """Draw the compiled onboard fences (blue, keep-in green) over the full-resolution fences
    (red), with the flight path (black) and its corridor (grey, dashed), in metres of the
    compile's frame, and save it as PNG.

    Parameters
    ----------
    records : list of FenceRecord
        The fences the compile read; those it left out as too far are not drawn.
    result : CompileResult
        What ``compile_fences`` returned.
    path : str or Path
        The PNG to write.
    """
    import shapely
    from matplotlib.lines import Line2D

    fig, ax = subplots(figsize=(9, 9))
    frame = result.frame
    corridor = result.corridor
    if corridor is not None and not corridor.area.is_empty:
        draw_polygons(
            ax, corridor.area, edgecolor="#757575", facecolor="#9e9e9e14", lw=1.0, ls="--"
        )
    dropped = set(result.dropped)
    for r in records:
        if r.kind in ("keep_out", "keep_in") and r.site_id not in dropped:
            draw_polygons(
                ax,
                frame.geom_to_local(r.geometry),
                edgecolor="#c62828",
                facecolor="#c6282833",
                lw=0.8,
            )
    for p in result.pieces:
        o = p.chosen
        draw_polygons(
            ax, o.local, edgecolor="#2e7d32" if p.inclusion else "#1565c0", facecolor="none", lw=1.3
        )
    handles = [
        Line2D([], [], color="#c62828", label="full-resolution fence"),
        Line2D([], [], color="#1565c0", lw=1.3, label="onboard fence"),
    ]
    if corridor is not None:
        if corridor.of_path:
            for line in shapely.get_parts(corridor.path):
                xy = shapely.get_coordinates(line)
                ax.plot(xy[:, 0], xy[:, 1], "-o", color="#212121", lw=1.2, ms=3)
            handles.append(Line2D([], [], color="#212121", marker="o", ms=3, label="flight path"))
        elif not corridor.area.is_empty:
            draw_polygons(ax, corridor.path, edgecolor="#212121", facecolor="none", lw=1.0)
            handles.append(Line2D([], [], color="#212121", label="operating area"))
        if not corridor.area.is_empty:
            handles.append(
                Line2D(
                    [], [], color="#757575", ls="--", label=f"corridor ({corridor.distance_m:g} m)"
                )
            )
    ax.legend(handles=handles, loc="upper right", fontsize=8)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    over = result.overshoot
    note = (
        f"\novershoot in the corridor {over.ratio:.3f} (airspace the onboard fence adds there, "
        "relative to what the full-resolution fences forbid there)"
        if over is not None and over.fenced_m2 > 0
        else ""
    )
    ax.set_title(
        f"Onboard fences: {len(result.items)} items, {result.bytes_used}/{result.profile.bytes} bytes "
        f"(blue) over full-resolution fences (red){note}",
        fontsize=10,
    )
    save_figure(fig, path)
