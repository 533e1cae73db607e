"""Eigenvector events (FRACAS SETEVN/PRINT): standard deviations, correlations and the
eigen-decomposition of the position and velocity blocks of a covariance."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fracas.filters.covariance import correlations

__all__ = ["EigenSummary", "eigen_summary"]


@dataclass
class EigenSummary:
    """sigma (n,), corr (n, n); position/velocity eigenvalues (3,) in km^2 and km^2/s^2
    (ascending), their square roots (1σ semi-axes, km and km/s) and eigenvectors (columns)."""

    sigma: np.ndarray
    corr: np.ndarray
    pos_eigval: np.ndarray
    pos_axes: np.ndarray
    pos_eigvec: np.ndarray
    vel_eigval: np.ndarray
    vel_axes: np.ndarray
    vel_eigvec: np.ndarray

    @property
    def pos_rss(self) -> float:
        return float(np.sqrt(np.sum(self.sigma[:3] ** 2)))

    @property
    def vel_rss(self) -> float:
        return float(np.sqrt(np.sum(self.sigma[3:6] ** 2)))


def eigen_summary(P: np.ndarray) -> EigenSummary:
    """The eigenvector event of one augmented covariance (state first: r km, v km/s, ...).

    Never raises on a bad matrix: a position or velocity block with a non-finite entry (or
    one ``eigh`` cannot decompose) gets NaN eigenvalues, semi-axes and eigenvectors, so one
    broken event leaves the others (and the results file) intact; the event's status is
    :func:`fracas.team.result.event_status`'s business."""
    P = np.asarray(P, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        P = 0.5 * (P + P.T)
        s, c = (np.asarray(a) for a in correlations(P))
    out = []
    for blk in (slice(0, 3), slice(3, 6)):
        with np.errstate(invalid="ignore", over="ignore"):
            B = 0.5 * (P[blk, blk] + P[blk, blk].T)
        w, V = np.full(3, np.nan), np.full((3, 3), np.nan)
        if np.all(np.isfinite(B)):
            try:
                w, V = np.linalg.eigh(B)
                V = V * np.where(V[np.argmax(np.abs(V), axis=0), np.arange(3)] < 0, -1.0, 1.0)  # largest entry > 0
            except np.linalg.LinAlgError:
                w, V = np.full(3, np.nan), np.full((3, 3), np.nan)
        out += [w, np.sqrt(np.clip(w, 0.0, None)), V]
    return EigenSummary(s, c, *out)
