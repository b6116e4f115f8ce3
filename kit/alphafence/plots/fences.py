"""Fences on a map: a build's fences over the restricted features, and the onboard fences a
compile chose over the full-resolution ones, in metres from the origin :func:`map_frame` names."""

from __future__ import annotations

import shapely

from alphafence.plots.common import (
    KIND_LABEL,
    draw_polygons,
    draw_restricted,
    kind_style,
    map_frame,
    save_figure,
    subplots,
)
from alphafence.plots.mapmarks import finish_map, site_names

ORDER = {"warning": 0, "keep_in": 1, "keep_out": 2}  # drawn in this order: keep-out on top


def fence_map(fences, sites, path, title="AlphaFence fences", note=None):
    """Draw every fence over the restricted features and save it as PNG.

    In metres east and north of the origin :func:`~alphafence.plots.common.map_frame` picks
    for these fences, with a scale bar, the names of the largest sites and a legend of the
    kinds drawn beside the map.

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

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    frame = map_frame([(f.kind, f.geometry) for f in fences])
    fig, ax = subplots(figsize=(9, 9))
    restricted = [s.frame.geom_to_wgs84(s.geometry) for s in sites]
    if restricted:
        draw_restricted(ax, frame.geom_to_local(shapely.GeometryCollection(restricted)))
    for f in sorted(fences, key=lambda f: ORDER.get(f.kind, 3)):
        style = kind_style(f.kind, label=KIND_LABEL.get(f.kind, f.kind))
        draw_polygons(ax, frame.geom_to_local(f.geometry), **style)
    ax.autoscale_view()
    finish_map(ax, frame, site_names(fences, frame))
    ax.set_title(title)
    if note:
        fig.text(0.01, 0.005, note, fontsize=7, color="#555")
    return save_figure(fig, path)


def _corridor(ax, corridor, to_map):
    """The corridor (grey, dashed) and its flight path or operating area (black)."""
    if corridor is None or corridor.area.is_empty:
        return
    draw_polygons(ax, to_map(corridor.area), label=f"corridor ({corridor.distance_m:g} m)",
                  edgecolor="#757575", facecolor="#9e9e9e14", lw=1.0, ls="--")  # fmt: skip
    if corridor.of_path:
        label = "flight path"
        for line in shapely.get_parts(to_map(corridor.path)):
            xy = shapely.get_coordinates(line)
            ax.plot(xy[:, 0], xy[:, 1], "-o", color="#212121", lw=1.2, ms=3, label=label)
            label = None
    else:
        draw_polygons(ax, to_map(corridor.path), label="operating area", edgecolor="#212121",
                      facecolor="none", lw=1.0)  # fmt: skip


def onboard_figure(records, result, path):
    """Draw the compiled onboard fences (blue, keep-in green) over the full-resolution fences
    (red), with the flight path (black) and its corridor (grey, dashed), and save it as PNG.

    In metres from the same origin as the build's map of these fences.

    Parameters
    ----------
    records : list of FenceRecord
        The fences the compile read; those it left out as too far are not drawn.
    result : CompileResult
        What ``compile_fences`` returned.
    path : str or Path
        The PNG to write.

    Returns
    -------
    matplotlib.figure.Figure
        The figure written (closed).
    """
    frame = map_frame([(r.kind, r.geometry) for r in records])

    def to_map(local):  # the compile's metres -> the map's
        return frame.geom_to_local(result.frame.geom_to_wgs84(local))

    fig, ax = subplots(figsize=(9, 9))
    _corridor(ax, result.corridor, to_map)
    dropped = set(result.dropped)
    label = "full-resolution fence"
    for r in records:
        if r.kind in ("keep_out", "keep_in") and r.site_id not in dropped:
            if draw_polygons(ax, frame.geom_to_local(r.geometry), label=label,
                             edgecolor="#c62828", facecolor="#c6282833", lw=0.8):  # fmt: skip
                label = None
    for p in result.pieces:
        inc = p.inclusion
        draw_polygons(ax, to_map(p.chosen.local), label="onboard inclusion" if inc else
                      "onboard fence", edgecolor="#2e7d32" if inc else "#1565c0",
                      facecolor="none", lw=1.3)  # fmt: skip
    ax.autoscale_view()
    shown = [r for r in records if r.site_id not in dropped]
    finish_map(ax, frame, site_names(shown, frame))
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
    return save_figure(fig, path)
