"""The two kinds of tableau of :mod:`fracas.integrate.tableaux` and their builders.

:class:`NystromTableau` (special Runge-Kutta-Nystrom methods, r'' = a(t, r)) and
:class:`RungeKuttaTableau` (explicit first-order methods on y = (r, v)); :func:`_nystrom` rounds a
tableau given as exact rationals (strings) once to float64 and keeps the rationals
(:func:`exact`); :func:`_lower` builds the strictly lower-triangular matrix of a first-order one.
The arrays are read-only numpy float64 arrays; a tableau is hashable by identity, so it can be a
static argument of ``jax.jit``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np


def _ro(x: object) -> np.ndarray:
    a = np.array(x, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class NystromTableau:
    """A (possibly embedded) special RKN method (velocity-independent accelerations).

    c (s,), a_bar (s, s) strictly lower triangular (position coupling), bbar (s,) position
    weights, b (s,) velocity weights of the propagated solution; bbar_low, b_low (s,) of the
    embedded one (None without an embedded pair).  ``fsal``: the last stage sits at c = 1 with
    its a_bar row equal to bbar, i.e. it evaluates the acceleration at the new position and
    can serve as stage 1 of the next step.
    """

    name: str
    c: np.ndarray
    a_bar: np.ndarray
    bbar: np.ndarray
    b: np.ndarray
    bbar_low: np.ndarray | None
    b_low: np.ndarray | None
    order: int
    embedded_order: int | None
    source: str
    fsal: bool = False
    rationals: dict = field(default=None, repr=False)

    @property
    def stages(self) -> int:
        return len(self.c)

    @property
    def ebar(self) -> np.ndarray | None:
        """Position error weights bbar - bbar_low (exact differences where the source gives them)."""
        return self._err("bbar")

    @property
    def e(self) -> np.ndarray | None:
        """Velocity error weights b - b_low."""
        return self._err("b")

    def _err(self, key: str) -> np.ndarray | None:
        if self.bbar_low is None:
            return None
        q = self.rationals
        if q is not None:
            return _ro([float(x - y) for x, y in zip(q[key], q[key + "_low"])])
        return _ro(getattr(self, key) - getattr(self, key + "_low"))


@dataclass(frozen=True, eq=False)
class RungeKuttaTableau:
    """An explicit first-order RK method with embedded error estimate(s).

    c (s,), a (s, s) strictly lower triangular, b (s,); ``e`` (s + 1,) error weights on the
    s stages plus the FSAL stage f(t + h, y1) (the first error estimate is h sum_i e_i k_i);
    ``e_aux`` a second estimate (DOP853's third-order one, combined as in Hairer's code).
    """

    name: str
    c: np.ndarray
    a: np.ndarray
    b: np.ndarray
    e: np.ndarray
    e_aux: np.ndarray | None
    order: int
    embedded_order: int
    aux_order: int | None
    source: str
    fsal: bool = True

    @property
    def stages(self) -> int:
        return len(self.c)


def _q(s: str) -> Fraction:
    return Fraction(s)


def _rationals(d: dict) -> dict:
    n = len(d["c"])
    a = [[Fraction(0)] * n for _ in range(n)]
    for i, row in enumerate(d["a_bar"], start=1):
        for j, x in enumerate(row):
            a[i][j] = _q(x)
    out = {k: [_q(x) for x in d[k]] for k in ("c", "bbar", "b", "bbar_low", "b_low") if k in d}
    out["a_bar"] = a
    return out


def _nystrom(
    name: str, d: dict, order: int, embedded_order: int | None, source: str, fsal: bool = False
) -> NystromTableau:
    q = _rationals(d)
    f = lambda v: _ro([float(x) for x in v])
    low = "bbar_low" in q
    return NystromTableau(
        name=name,
        c=f(q["c"]),
        a_bar=_ro([[float(x) for x in row] for row in q["a_bar"]]),
        bbar=f(q["bbar"]),
        b=f(q["b"]),
        bbar_low=f(q["bbar_low"]) if low else None,
        b_low=f(q["b_low"]) if low else None,
        order=order,
        embedded_order=embedded_order,
        source=source,
        fsal=fsal,
        rationals=q,
    )


def exact(tab: NystromTableau) -> dict:
    """The exact rationals of a Nystrom tableau (keys c, a_bar, bbar, b, bbar_low, b_low)."""
    return tab.rationals


def _lower(rows: Sequence[Sequence[float]], n: int) -> np.ndarray:
    a = np.zeros((n, n))
    for i, row in enumerate(rows, start=1):
        a[i, : len(row)] = row
    return _ro(a)
