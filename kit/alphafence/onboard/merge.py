"""Fitting pieces into the storage budget: merging the nearest keep-out pieces until the
cheapest options fit, then spending what is left where it saves the most area."""

from __future__ import annotations

import math

import numpy as np
import shapely
import shapely.errors

from alphafence.build.fences import enclosing_circle
from alphafence.errors import InputError
from alphafence.geo.alpha import alpha_shape
from alphafence.onboard.options import Piece, piece_options


def totals(pieces):
    """Items and bytes the pieces' chosen options take together.

    Returns
    -------
    items : int
    bytes : int
    """
    return sum(p.chosen.items for p in pieces), sum(p.chosen.bytes for p in pieces)


def _cheapest_circle(piece):
    c = piece.options[0].circle
    if c is None:
        c = enclosing_circle(piece.local)
    return c


def _best_merge(pieces, neighbours=4):
    """The pair of neighbouring keep-out pieces whose merge adds the least area, estimated
    as the larger of what their convex hull adds (large pieces stay polygons) and what
    their common circle adds (small pieces end up as circles)."""
    outs = [i for i, p in enumerate(pieces) if not p.inclusion]
    if len(outs) < 2:
        return None
    geoms = np.array([pieces[i].local for i in outs], dtype=object)
    k = min(neighbours + 1, len(outs))
    pairs = set()
    for a in range(len(outs)):
        d = shapely.distance(geoms[a], geoms)
        for b in np.argsort(d)[:k]:
            if a != b:
                pairs.add((min(a, int(b)), max(a, int(b))))
    a, b = np.array(sorted(pairs)).T
    hulls = shapely.convex_hull(geoms)
    both = shapely.convex_hull(
        np.array(
            [shapely.GeometryCollection([geoms[i], geoms[j]]) for i, j in zip(a, b)], dtype=object
        )
    )
    hull_cost = shapely.area(both) - shapely.area(hulls[a]) - shapely.area(hulls[b])
    # small pieces end up as circles: what their common circle adds counts too
    c = np.array([_cheapest_circle(pieces[i]) for i in outs])
    x, y, r = c[:, 0], c[:, 1], c[:, 2]
    d = np.hypot(x[a] - x[b], y[a] - y[b])
    big = np.maximum(r[a], r[b])
    R = np.where(d + np.minimum(r[a], r[b]) <= big, big, (d + r[a] + r[b]) / 2)
    circle_cost = np.pi * (R**2 - r[a] ** 2 - r[b] ** 2)
    cost = np.maximum(hull_cost, circle_cost)
    j = int(np.argmin(cost))
    return float(cost[j]), outs[a[j]], outs[b[j]]


def _merge(pieces, a, b, profile, merges):
    pair = shapely.GeometryCollection([pieces[a].local, pieces[b].local])
    try:
        joined, _ = alpha_shape(shapely.union(pieces[a].local, pieces[b].local))
    except shapely.errors.GEOSException:
        joined = None
    if joined is None or joined.geom_type != "Polygon":  # not joined into one piece: the hull
        joined = shapely.convex_hull(pair)
    merged = Piece(
        pieces[a].sources + pieces[b].sources,
        False,
        joined,
        piece_options(joined, False, profile.max_polygon_vertices),
        merged=True,
    )
    merges.append(tuple(merged.sources))
    pieces[a] = merged
    del pieces[b]


def fit_by_merging(pieces, budget_items, budget_bytes, profile, merges):
    """Merge the cheapest pair of neighbouring keep-out pieces until every piece's cheapest
    option fits the budget.

    Parameters
    ----------
    pieces : list of Piece
        Changed in place.
    budget_items, budget_bytes : int
        What the pieces may take.
    profile : Profile
        The vehicle's storage (its polygon vertex limit; its name for the message).
    merges : list
        The ``sources`` of every merge made are appended.

    Raises
    ------
    InputError
        When no merge is left and the pieces still do not fit.
    """
    while True:
        items, nbytes = totals(pieces)
        if items <= budget_items and nbytes <= budget_bytes:
            return
        best = _best_merge(pieces)
        if best is None:
            raise InputError(
                "compile",
                f"the fences near the area do not fit a {profile.name} "
                f"({items} items / {nbytes} bytes for {budget_items} / {budget_bytes})",
            )
        _merge(pieces, best[1], best[2], profile, merges)


def merge_to_upgrade(pieces, budget_items, budget_bytes, profile, merges, rounds=40):
    """Merge two small neighbours when the storage it frees buys a larger saving elsewhere
    (typically: two substations share a circle so the airport keeps its shape).

    Each round tries the cheapest merge followed by :func:`upgrade`, and keeps it only when
    the total area lost goes down. ``pieces`` and ``merges`` change in place.
    """
    for _ in range(rounds):
        best = _best_merge(pieces)
        if best is None:
            return
        trial = [
            Piece(p.sources, p.inclusion, p.local, p.options, p.choice, p.merged, p.outward)
            for p in pieces
        ]
        before = sum(p.chosen.loss for p in pieces)
        trial_merges = []
        _merge(trial, best[1], best[2], profile, trial_merges)
        upgrade(trial, budget_items, budget_bytes)
        after = sum(p.chosen.loss for p in trial)
        if after >= before:
            return
        pieces[:] = trial
        merges.extend(trial_merges)


def upgrade(pieces, budget_items, budget_bytes):
    """Greedy multiple-choice knapsack: spend the budget where it saves most area.

    Repeatedly moves the piece whose next better option saves the most area per share of
    the budget it costs, while the budget allows; each piece's ``choice`` changes in place.
    """
    while True:
        items, nbytes = totals(pieces)
        best = None
        for p in pieces:
            cur = p.chosen
            for j in range(p.choice + 1, len(p.options)):
                o = p.options[j]
                di, db = o.items - cur.items, o.bytes - cur.bytes
                if items + di > budget_items or nbytes + db > budget_bytes:
                    continue
                gain = cur.loss - o.loss
                cost = di / budget_items + db / budget_bytes
                ratio = gain / cost if cost > 0 else math.inf
                if gain > 0 and (best is None or ratio > best[0]):
                    best = (ratio, p, j)
        if best is None:
            return
        best[1].choice = best[2]
