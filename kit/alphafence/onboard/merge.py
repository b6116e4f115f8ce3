"""Fitting pieces into the storage budget: merging the nearest keep-out pieces until the
cheapest options fit, then spending what is left where it saves the most area."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import shapely
import shapely.errors

from alphafence.errors import InputError, need
from alphafence.fencing.fences import enclosing_circle
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


def _best_merge(pieces, neighbours=4, model=None):
    """The pair of neighbouring keep-out pieces whose merge adds the least area, estimated
    as the larger of what their convex hull adds (large pieces stay polygons) and what
    their common circle adds (small pieces end up as circles); in the corridor, with a
    ``model``."""
    area = shapely.area if model is None else model.corridor.weighted_area
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
    hull_area = area(hulls)
    hull_cost = area(both) - hull_area[a] - hull_area[b]
    # small pieces end up as circles: what their common circle adds counts too
    c = np.array([_cheapest_circle(pieces[i]) for i in outs])
    x, y, r = c[:, 0], c[:, 1], c[:, 2]
    d = np.hypot(x[a] - x[b], y[a] - y[b])
    big = np.maximum(r[a], r[b])
    R = np.where(d + np.minimum(r[a], r[b]) <= big, big, (d + r[a] + r[b]) / 2)
    if model is None:
        circle_cost = np.pi * (R**2 - r[a] ** 2 - r[b] ** 2)
    else:
        own = area(shapely.buffer(shapely.points(x, y), r, quad_segs=8))
        cx = np.where(R == big, np.where(r[a] >= r[b], x[a], x[b]), 0.0)
        cy = np.where(R == big, np.where(r[a] >= r[b], y[a], y[b]), 0.0)
        far = R > big
        t = np.where(far, (R - r[a]) / np.maximum(d, 1e-12), 0.0)
        cx = np.where(far, x[a] + (x[b] - x[a]) * t, cx)
        cy = np.where(far, y[a] + (y[b] - y[a]) * t, cy)
        common = area(shapely.buffer(shapely.points(cx, cy), R, quad_segs=8))
        circle_cost = common - own[a] - own[b]
    cost = np.maximum(hull_cost, circle_cost)
    clear = None if model is None else model.clear
    if clear is not None:  # no merge may fill the space round home (or the position)
        real = [pieces[i].local if pieces[i].required is None else pieces[i].required for i in outs]
        needs = np.array([clear.needs(g, False) for g in real])
        cost = np.where(clear.spans(both, np.minimum(needs[a], needs[b])), np.inf, cost)
        if not np.isfinite(cost).any():
            return None
    j = int(np.argmin(cost))
    return float(cost[j]), outs[a[j]], outs[b[j]]


def _merge(pieces, a, b, profile, merges, model=None):
    pair_of = (pieces[a], pieces[b])
    pair = shapely.GeometryCollection([pieces[a].local, pieces[b].local])
    need(("scipy", "merging fences to fit the vehicle's storage"))  # the alpha shape's
    try:
        joined, _ = alpha_shape(shapely.union(pieces[a].local, pieces[b].local))
    except shapely.errors.GEOSException:
        joined = None
    hull = shapely.convex_hull(pair)
    if joined is None or joined.geom_type != "Polygon":  # not joined into one piece: the hull
        joined = hull
    required = shapely.union(*(p.local if p.required is None else p.required for p in pair_of))
    for shape in (joined, hull):
        merged = _merged(pieces[a].sources + pieces[b].sources, shape, required, profile)
        if model is None or model.rescore(merged):  # else it reached over home: the hull
            break
    else:
        raise InputError("compile", f"merging {', '.join(merged.sources)} would reach over "
                         f"{model.clear.keep.points[0]}: narrow the area")  # fmt: skip
    merges.append(tuple(merged.sources))
    pieces[a] = merged
    del pieces[b]


def _merged(sources, joined, required, profile):
    """The piece of fences ``sources`` merged into ``joined`` (metric), ``required`` their
    union."""
    options = piece_options(joined, False, profile.max_polygon_vertices)
    gap = max(joined.area - required.area, 0.0)  # what the merge fills between the fences
    for o in options:
        o.loss += gap
    return Piece(sources, False, joined, options, merged=True, required=required)


def fit_by_merging(pieces, budget_items, budget_bytes, profile, merges, model=None):
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
    model : LossModel, optional
        Counts area in the corridor; without it, everywhere alike.

    Raises
    ------
    InputError
        When no merge is left and the pieces still do not fit.
    """
    while True:
        items, nbytes = totals(pieces)
        if items <= budget_items and nbytes <= budget_bytes:
            return
        best = _best_merge(pieces, model=model)
        if best is None:
            clear = "" if model is None or model.clear is None else (
                f"; no merge may come within {model.clear.keep.clearance_m:g} m of "
                + " or ".join(p.label for p in model.clear.keep.points))  # fmt: skip
            raise InputError(
                "compile",
                f"the fences near the area do not fit a {profile.name} "
                f"({items} items / {nbytes} bytes for {budget_items} / {budget_bytes}){clear}",
            )
        _merge(pieces, best[1], best[2], profile, merges, model)


def merge_to_upgrade(
    pieces, budget_items, budget_bytes, profile, merges, rounds=40, model=None, lookahead=4
):
    """Merge small neighbours when the storage it frees buys a larger saving elsewhere
    (typically: substations share a circle so the airport keeps its shape).

    Each round tries up to ``lookahead`` of the cheapest merges in a row, each followed by
    :func:`upgrade` (one circle's 13 bytes rarely buy a better polygon; a few do), and keeps
    the shortest run that lowers the total area lost. ``pieces`` and ``merges`` change in
    place; ``model`` as for :func:`fit_by_merging`.
    """
    for _ in range(rounds):
        if all(p.choice == len(p.options) - 1 for p in pieces):
            return  # every piece has its best shape: a merge could only add area
        before = sum(p.chosen.loss for p in pieces)
        trial = [dataclasses.replace(p) for p in pieces]
        trial_merges = []
        for _step in range(lookahead):
            best = _best_merge(trial, model=model)
            if best is None:
                return
            _merge(trial, best[1], best[2], profile, trial_merges, model)
            upgrade(trial, budget_items, budget_bytes)
            items, nbytes = totals(trial)  # a merge kept clear of home may cost more
            fits = items <= budget_items and nbytes <= budget_bytes
            if fits and sum(p.chosen.loss for p in trial) < before:
                break
        else:
            return
        pieces[:] = trial
        merges.extend(trial_merges)


DP_STATES = 250_000  # the exact allocation runs when its table is at most this large
ITEM_MIN_BYTES = 8  # no fence item takes fewer bytes (a vertex 8, a circle 13, a return point 9)


def upgrade(pieces, budget_items, budget_bytes):
    """Choose each piece's option so that together they lose the least area within the
    budget (a multiple-choice knapsack); each piece's ``choice`` changes in place.

    Small budgets (a board's own storage) are solved exactly by dynamic programming over the
    bytes (and the items, when an item limit binds before the bytes do): the greedy choice
    spends 13-byte steps on small fences and never affords the 70 bytes that turn an
    airport's circle into a polygon. Large budgets (file storage) are filled greedily: the
    piece whose next better option saves the most area per share of the budget first.
    """
    if not _allocate(pieces, budget_items, budget_bytes):
        _greedy(pieces, budget_items, budget_bytes)


def _allocate(pieces, budget_items, budget_bytes):
    """The exact allocation, when the table is small enough; False when it is not run (or
    nothing fits, which the caller's merging rules out)."""
    if not pieces:
        return True
    dense = any(o.items * ITEM_MIN_BYTES > o.bytes for p in pieces for o in p.options)
    # the bytes bound the items unless the item limit is lower (or an item is under 8 bytes)
    n_items = budget_items if dense or budget_items * ITEM_MIN_BYTES < budget_bytes else 0
    if (budget_bytes + 1) * (n_items + 1) > DP_STATES:
        return False
    shape = (budget_bytes + 1, n_items + 1)
    best = np.full(shape, np.inf)
    best[0, 0] = 0.0
    picks = []
    for p in pieces:
        new = np.full(shape, np.inf)
        pick = np.full(shape, -1, dtype=np.int16)
        for j, o in enumerate(p.options):
            di = o.items if n_items else 0
            if o.bytes > budget_bytes or di > n_items:
                continue
            cand = np.full(shape, np.inf)
            cand[o.bytes :, di:] = best[: shape[0] - o.bytes, : shape[1] - di] + o.loss
            better = cand < new
            new[better] = cand[better]
            pick[better] = j
        best = new
        picks.append(pick)
    at = np.unravel_index(int(np.argmin(best)), shape)
    if not np.isfinite(best[at]):
        return False
    b, i = int(at[0]), int(at[1])
    for p, pick in zip(reversed(pieces), reversed(picks)):
        j = int(pick[b, i])
        p.choice = j
        b -= p.options[j].bytes
        i -= p.options[j].items if n_items else 0
    return True


def _greedy(pieces, budget_items, budget_bytes):
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
