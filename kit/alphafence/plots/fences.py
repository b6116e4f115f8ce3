"""Pictures: fences on a map, and the methods side by side."""

from __future__ import annotations

import io
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import shapely  # noqa: E402

from alphafence.formats.atomic import write_bytes_atomic  # noqa: E402

KIND_STYLE = {
    "keep_out": dict(edgecolor="#c62828", facecolor="#c6282822", lw=1.4),
    "warning": dict(edgecolor="#ef8f00", facecolor="none", lw=1.0, ls="--"),
    "keep_in": dict(edgecolor="#2e7d32", facecolor="none", lw=1.6),
}
METHOD_COLOR = {"alpha": "#1565c0", "polygon": "#6a1b9a", "circle": "#ef6c00", "exact": "#2e7d32"}


def _draw(ax, geom, **style):
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path

    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon":
            continue
        rings = [np.asarray(poly.exterior.coords)] + [np.asarray(r.coords) for r in poly.interiors]
        verts = np.concatenate(rings)
        codes = np.concatenate(
            [[Path.MOVETO] + [Path.LINETO] * (len(r) - 2) + [Path.CLOSEPOLY] for r in rings]
        )
        ax.add_patch(PathPatch(Path(verts, codes), **style))


def _draw_restricted(ax, geom):
    for part in shapely.get_parts(geom):
        if part.geom_type == "Point":
            ax.plot(part.x, part.y, "k.", ms=3)
        elif part.geom_type == "LineString":
            ax.plot(*np.asarray(part.coords).T, color="#555", lw=1)
    _draw(ax, geom, edgecolor="#444", facecolor="#9e9e9e", lw=0.5)


def _save(fig, path):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())


def fence_map(fences, sites, path, title="AlphaFence fences", note=None):
    """All fences (WGS84) over the restricted features, equal-area-ish aspect."""
    fig, ax = plt.subplots(figsize=(9, 9))
    for s in sites:
        _draw_restricted(ax, s.frame.geom_to_wgs84(s.geometry))
    order = {"warning": 0, "keep_in": 1, "keep_out": 2}
    for f in sorted(fences, key=lambda f: order.get(f.kind, 3)):
        _draw(ax, f.geometry, **KIND_STYLE.get(f.kind, KIND_STYLE["keep_out"]))
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
    _save(fig, path)


def comparison_figure(sites, by_method, path, note=None):
    """Rows: a few telling sites; columns: methods. Metric axes (the site's frame)."""
    methods = list(by_method)
    fig, axes = plt.subplots(
        len(sites), len(methods), figsize=(3.2 * len(methods), 3.2 * len(sites)), squeeze=False
    )
    for r, site in enumerate(sites):
        for c, m in enumerate(methods):
            ax = axes[r][c]
            fence = by_method[m][site.site_id]
            _draw(
                ax,
                fence.local,
                edgecolor=METHOD_COLOR.get(m, "k"),
                facecolor=METHOD_COLOR.get(m, "k") + "22",
                lw=1.5,
            )
            _draw_restricted(ax, site.geometry)
            ax.autoscale_view()
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            g = site.geometry.area
            over = (
                (fence.area_m2 - shapely.intersection(fence.local, site.geometry).area) / g
                if g
                else 0
            )
            ax.set_title(f"{m}: {fence.vertices} v, +{100 * over:.0f}%", fontsize=9)
            if c == 0:
                label = (site.name or site.site_id)[:28]
                ax.set_ylabel(f"{label}\n({site.category})", fontsize=8)
        # the same extent across a row, so areas compare by eye
        boxes = np.array([axes[r][c].dataLim.bounds for c in range(len(methods))])
        x0, y0 = boxes[:, 0].min(), boxes[:, 1].min()
        x1 = (boxes[:, 0] + boxes[:, 2]).max()
        y1 = (boxes[:, 1] + boxes[:, 3]).max()
        for c in range(len(methods)):
            axes[r][c].set_xlim(x0, x1)
            axes[r][c].set_ylim(y0, y1)
    fig.suptitle("Fence methods side by side (grey: restricted area; +%: overshoot)", fontsize=11)
    if note:
        fig.text(0.01, 0.003, note, fontsize=7, color="#555")
    _save(fig, path)


def onboard_figure(records, result, path):
    """Compiled onboard fences (blue) over the full-resolution fences (red), metric."""
    fig, ax = plt.subplots(figsize=(9, 9))
    frame = result.frame
    dropped = set(result.dropped)
    for r in records:
        if r.kind in ("keep_out", "keep_in") and r.site_id not in dropped:
            _draw(
                ax,
                frame.geom_to_local(r.geometry),
                edgecolor="#c62828",
                facecolor="#c6282833",
                lw=0.8,
            )
    for p in result.pieces:
        o = p.chosen
        _draw(
            ax, o.local, edgecolor="#2e7d32" if p.inclusion else "#1565c0", facecolor="none", lw=1.3
        )
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(
        f"Onboard fences: {len(result.items)} items, {result.bytes_used}/{result.profile.bytes} bytes "
        f"(blue) over full-resolution fences (red)",
        fontsize=10,
    )
    _save(fig, path)
