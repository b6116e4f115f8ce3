"""Smoothing a roadmap path by line of sight: shortcuts to the farthest visible vertex, then
corners cut as deep as the clearance allows, never adding metres inside warning layers.

Each function takes the :class:`~alphafence.route.roadmap.Roadmap` the path was found on and
uses only its public predicates (``clear``, ``warning_length``) and attributes.
"""

from __future__ import annotations

import numpy as np


def shortcut(roadmap, P):
    """Greedy: from each kept vertex jump to the farthest one in clear line of sight that
    does not add warning-layer metres."""
    n = len(P)
    if n <= 2:
        return P
    wl = np.concatenate([[0.0], np.cumsum(roadmap.warning_length(P[:-1], P[1:]))])
    keep = [0]
    i = 0
    while i < n - 1:
        rest = n - 1 - i
        if rest <= 192:
            cand = np.arange(i + 2, n)
        else:
            near = np.arange(i + 2, i + 130)
            far = np.unique(np.linspace(i + 130, n - 1, 64).astype(int))
            cand = np.concatenate([near, far])
        j = i + 1
        if cand.size:
            a = np.repeat(P[i : i + 1], len(cand), axis=0)
            ok = roadmap.clear(a, P[cand])
            if roadmap.wtree is not None and ok.any():
                c2 = cand[ok]
                extra = roadmap.warning_length(a[: len(c2)], P[c2]) - (wl[c2] - wl[i])
                ok[np.flatnonzero(ok)[extra > 1e-6]] = False
            if ok.any():
                j = int(cand[ok].max())
        keep.append(j)
        i = j
    return P[keep]


def cut_corners(roadmap, P):
    """Cut every corner as deep as line of sight allows: vertex i becomes two points on its
    legs, at the largest fraction u <= 1/2 of each leg whose chord is clear (and adds no
    warning-layer metres). Each leg is shared by at most two cuts of at most half, so the
    rest of the path is unchanged and stays clear."""
    n = len(P)
    if n <= 2:
        return P
    v = P[1:-1]
    da = P[:-2] - v
    db = P[2:] - v
    lo = np.zeros(n - 2)
    hi = np.full(n - 2, 0.5)
    warn = roadmap.wtree is not None
    if warn:
        wa = roadmap.warning_length(P[:-2], v)
        wb = roadmap.warning_length(v, P[2:])
    for it in range(9):
        t = hi if it == 0 else 0.5 * (lo + hi)
        pa = v + t[:, None] * da
        pb = v + t[:, None] * db
        ok = roadmap.clear(pa, pb)
        if warn:  # a chord may enter warning layers only where both legs were inside
            ok &= roadmap.warning_length(pa, pb) <= np.where(wa + wb > 0, wa + wb, 0) + 1e-6
        lo = np.where(ok, t, lo)
        hi = np.where(ok, hi, t)
        if it == 0 and ok.all():
            break
    # no cuts shorter than half the sample spacing: they would only add waypoints
    short = np.minimum(np.hypot(*da.T), np.hypot(*db.T))
    lo[lo * short < 0.5 * roadmap.spacing] = 0.0
    out = [P[:1]]
    for k in range(n - 2):
        if lo[k] > 0.0:
            out.append(np.array([v[k] + lo[k] * da[k], v[k] + lo[k] * db[k]]))
        else:
            out.append(v[k : k + 1])
    out.append(P[-1:])
    return np.concatenate(out)


def smooth_path(roadmap, P, rounds=12):
    """A path pulled taut by line of sight: :func:`shortcut`, then rounds of
    :func:`cut_corners` and :func:`shortcut` while they shorten it (by at least a thousandth
    of the sample spacing); (near-)duplicate points dropped.

    Parameters
    ----------
    roadmap : Roadmap
        The roadmap the path was found on.
    P : ndarray, shape (n, 2)
        The path, metres, start first.
    rounds : int
        At most this many rounds of cutting.

    Returns
    -------
    ndarray, shape (m, 2)
        Same start and goal, never closer to keep-out fences than the clearance.
    """
    P = shortcut(roadmap, P)
    length = np.hypot(*np.diff(P, axis=0).T).sum()
    for _ in range(rounds):
        if len(P) <= 2:
            break
        P = shortcut(roadmap, cut_corners(roadmap, P))
        new = np.hypot(*np.diff(P, axis=0).T).sum()
        if length - new < 1e-3 * roadmap.spacing:
            break
        length = new
    # drop (near-)duplicate points
    keep = np.concatenate([[True], np.hypot(*np.diff(P, axis=0).T) > 1e-6])
    keep[-1] = True
    return P[keep]
