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
:func:`fracas.pipeline.run_tom` runs them.
"""

from __future__ import annotations

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


def burns_from_segments(
    edges_s: np.ndarray,
    throttle: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    degree: int = 3,
    on: float = 0.02,
) -> list[Burn]:
    """The burns of a solved segment pass.

    ``edges_s`` (N + 1,) segment edges (s); ``throttle``, ``alpha``, ``beta`` (N,) the solution.
    A burn is a maximal run of segments with throttle > ``on``.  Its start moves into its first
    segment by (1 - throttle) of that segment's length, its end back from its last segment's end
    likewise (a partial edge segment keeps its impulse, ∫ throttle dt); partial segments inside a
    run count as thrusting.  The pointing law of a burn is the throttle-weighted Legendre fit of
    degree ``degree`` through the segments' midpoints (alpha unwrapped first, so a run through
    ±180° is continuous).  No burn: an empty list.
    """
    edges = np.asarray(edges_s, float)
    thr = np.clip(np.asarray(throttle, float), 0.0, 1.0)
    alpha = np.unwrap(np.asarray(alpha, float))
    beta = np.asarray(beta, float)
    burns: list[Burn] = []
    n = thr.size
    k = 0
    while k < n:
        if thr[k] <= on:
            k += 1
            continue
        j = k
        while j + 1 < n and thr[j + 1] > on:
            j += 1
        start = edges[k] + (1.0 - thr[k]) * (edges[k + 1] - edges[k])
        stop = edges[j + 1] - (1.0 - thr[j]) * (edges[j + 1] - edges[j]) if j > k else edges[k + 1]
        if j == k:  # one partial segment: centre its impulse in it
            mid = 0.5 * (edges[k] + edges[k + 1])
            half = 0.5 * thr[k] * (edges[k + 1] - edges[k])
            start, stop = mid - half, mid + half
        mids = 0.5 * (edges[k : j + 1] + edges[k + 1 : j + 2])
        s = np.clip((2.0 * mids - start - stop) / max(stop - start, 1e-300), -1.0, 1.0)
        w = thr[k : j + 1] * (edges[k + 1 : j + 2] - edges[k : j + 1])
        ca = legendre_fit(s, alpha[k : j + 1], w, degree)
        cb = legendre_fit(s, beta[k : j + 1], w, degree)
        mean_alpha = float(-np.remainder(-ca[0] + np.pi, 2.0 * np.pi) + np.pi)
        burns.append(Burn(float(start), float(stop), mean_alpha, float(cb[0]), tuple(ca[1:]), tuple(cb[1:])))
        k = j + 1
    return burns
