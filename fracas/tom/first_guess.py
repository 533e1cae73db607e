"""TOM's automatic first guess for low-thrust problems: a throttle-segment pass, then burns.

Not in the FRACAS report (its UPHILL starts from the analyst's controls).  A minimum-propellant
low-thrust problem started from "thrust along the velocity on a few arcs" rarely converges:
the burn structure (how many burns, where) and the pointing are both unknown, and a search on
switch times from a wrong structure stalls in a poor local optimum.  Direct methods avoid the
combinatorics by letting a throttle vary on a fixed grid; this module does the same in two
passes, each an ordinary TOM problem:

1. **Segments**: the thrust window cut into N contiguous arcs, each with its own throttle in
   [0, 1] and constant pointing (velocity frame), every one a control; start at half throttle,
   thrust along the velocity.  The optimum of this problem is nearly bang-bang: segments at
   full throttle, coasting segments at zero, a few partial ones at the burn edges.
2. **Burns**: :func:`burns_from_segments` merges runs of thrusting segments into burns (full
   throttle, edges moved so that each partial edge segment keeps its impulse), and
   :func:`legendre_fit` fits each burn's pointing by a Legendre series in the burn's normalised
   time.  The second pass optimizes the burns' switch times and pointing laws.

Arrays in, arrays out (no deck objects): :mod:`fracas.build.tom` builds the two problems and
:func:`fracas.modes.tom.run_tom` runs them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Burn", "burns_from_segments", "legendre_fit", "legendre_values"]


@dataclass(frozen=True)
class Burn:
    """One burn of the second pass: start and stop (s from the epoch), the mean angles (rad) and
    the Legendre P1..Pk coefficients of alpha and beta (rad) in s = (2t - start - stop)/(stop - start)."""

    start_s: float
    stop_s: float
    alpha: float
    beta: float
    alpha_legendre: tuple[float, ...]
    beta_legendre: tuple[float, ...]


def legendre_values(s: np.ndarray, degree: int) -> np.ndarray:
    """(len(s), degree + 1): P0..P_degree at s (Bonnet's recursion)."""
    s = np.asarray(s, float)
    out = np.ones((s.size, degree + 1))
    if degree >= 1:
        out[:, 1] = s
    for n in range(1, degree):
        out[:, n + 1] = ((2 * n + 1) * s * out[:, n] - n * out[:, n - 1]) / (n + 1)
    return out


def legendre_fit(s: np.ndarray, values: np.ndarray, weights: np.ndarray, degree: int) -> np.ndarray:
    """Weighted least-squares coefficients c0..c_d of sum c_n P_n(s) through (s, values); the degree
    is lowered to (number of points - 1) when there are fewer points (missing ones are zero)."""
    s, values, w = (np.asarray(a, float) for a in (s, values, weights))
    d = min(degree, s.size - 1)
    out = np.zeros(degree + 1)
    if s.size == 0:
        return out
    a = legendre_values(s, d) * np.sqrt(w)[:, None]
    coef, *_ = np.linalg.lstsq(a, values * np.sqrt(w), rcond=None)
    out[: d + 1] = coef
    return out


def _fit(edges, thr, alpha, beta, k, j, start, stop, degree):
    """The Burn of segments k..j over [start, stop] and its worst fit error (rad) at the midpoints
    of each segment's thrusting part (a partial edge segment thrusts from ``start`` / until ``stop``)."""
    lo = np.maximum(edges[k : j + 1], start)
    hi = np.minimum(edges[k + 1 : j + 2], stop)
    mids = 0.5 * (lo + hi)
    s = np.clip((2.0 * mids - start - stop) / max(stop - start, 1e-300), -1.0, 1.0)
    w = np.maximum(thr[k : j + 1], 1e-3) * (edges[k + 1 : j + 2] - edges[k : j + 1])
    ca = legendre_fit(s, alpha[k : j + 1], w, degree)
    cb = legendre_fit(s, beta[k : j + 1], w, degree)
    basis = legendre_values(s, degree)
    err = max(
        float(np.max(np.abs(basis @ ca - alpha[k : j + 1]))),
        float(np.max(np.abs(basis @ cb - beta[k : j + 1]))),
    )
    mean_alpha = float(-np.remainder(-ca[0] + np.pi, 2.0 * np.pi) + np.pi)
    return Burn(float(start), float(stop), mean_alpha, float(cb[0]), tuple(ca[1:]), tuple(cb[1:])), err


def burns_from_segments(
    edges_s: np.ndarray,
    throttle: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    degree: int = 3,
    on: float = 0.02,
    max_fit_error_rad: float = math.inf,
    max_arcs: int = 1,
) -> list[list[Burn]]:
    """The burns of a solved segment pass, each as a list of contiguous arcs.

    ``edges_s`` (N + 1,) segment edges (s); ``throttle``, ``alpha``, ``beta`` (N,) the solution.
    A burn is a maximal run of segments with throttle > ``on``.  Its start moves into its first
    segment by (1 - throttle) of that segment's length, its end back from its last segment's end
    likewise (a partial edge segment keeps its impulse, ∫ throttle dt); a lone partial segment
    becomes a burn of throttle x its length centred in it; partial segments inside a run count as
    thrusting.  Each burn's pointing is the throttle-weighted Legendre fit of degree ``degree``
    through its segments' midpoints (alpha unwrapped first, so a run through ±180° is
    continuous); when the worst fit error exceeds ``max_fit_error_rad`` the burn is cut into
    2, 3, ... ``max_arcs`` contiguous arcs of (nearly) equal segment counts, each with its own law,
    until it fits (arcs meet at segment edges).  No burn: an empty list.
    """
    edges = np.asarray(edges_s, float)
    thr = np.clip(np.asarray(throttle, float), 0.0, 1.0)
    alpha = np.unwrap(np.asarray(alpha, float))
    beta = np.asarray(beta, float)
    burns: list[list[Burn]] = []
    n = thr.size
    k = 0
    while k < n:
        if thr[k] <= on:
            k += 1
            continue
        j = k
        while j + 1 < n and thr[j + 1] > on:
            j += 1
        if j == k:  # one partial segment: centre its impulse in it
            mid = 0.5 * (edges[k] + edges[k + 1])
            half = 0.5 * thr[k] * (edges[k + 1] - edges[k])
            start, stop = mid - half, mid + half
        else:
            start = edges[k] + (1.0 - thr[k]) * (edges[k + 1] - edges[k])
            stop = edges[j + 1] - (1.0 - thr[j]) * (edges[j + 1] - edges[j])
        count = j - k + 1
        pieces: list[Burn] = []
        for n_arcs in range(1, max(1, min(max_arcs, count)) + 1):
            cuts = [k + round(i * count / n_arcs) for i in range(n_arcs + 1)]
            pieces, worst = [], 0.0
            for a, b in zip(cuts[:-1], cuts[1:]):
                t0 = start if a == k else edges[a]
                t1 = stop if b == j + 1 else edges[b]
                burn, err = _fit(edges, thr, alpha, beta, a, b - 1, t0, t1, degree)
                pieces.append(burn)
                worst = max(worst, err)
            if worst <= max_fit_error_rad:
                break
        burns.append(pieces)
        k = j + 1
    return burns
