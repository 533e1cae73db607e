"""Runge-Kutta(-Nystrom) stages as data: one traced stage function per step program.

A step of an s-stage method used to be a Python loop over the stages, so the force model
was traced (and compiled) once per stage: 17 copies for DPRKN12, 13 for DOP853 (issue 23).
Here the tableau is a set of arrays and the stages run under ``lax.fori_loop``: the stage
function is traced **once**, whatever the method, and each stage's value is written into a
stage array (which also keeps XLA CPU from re-fusing early stages into later ones, the job
``highorder._materialise`` did for the unrolled loop; ../shared/perf-notes.md item 2).

:func:`plan_of_tableau` turns a tableau of :mod:`fracas.integrate.tableaux` into a :class:`StagePlan`
(numpy, static, cached per method):

* special RKN methods (y'' = f(t, y)): stages that repeat an earlier stage (same node and the
  same position coupling: RKN4's two stages at t + h/2) are folded into it, so each distinct
  acceleration is evaluated once;
* first-order methods (DOP853): the stage f(t + h, y1) of the error estimate is appended as
  an extra stage whose coupling row is the weights b, so the step's last evaluation is the
  same traced function too (its input is y1 itself).

The stage states and values may be any pytree of arrays (a state, a state with its
variational matrices, ...): every leaf gets a stage axis in front.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.integrate.tableaux import NystromTableau, RungeKuttaTableau

__all__ = ["StagePlan", "StageValues", "plan_of_tableau", "nystrom_stages", "rk_stages", "weighted"]


class StagePlan(NamedTuple):
    """A method's tableau as arrays (numpy; static per method).

    c (S,): stage nodes (fraction of the step); a (S, S): strictly lower coupling (RKN: the
    position coupling a_bar; RK: a); node (S,): index of each stage's node in ``nodes``;
    nodes (U,): the distinct nodes, 1.0 always included (body states and conics are prepared
    once per step at these); b, bbar (S,): velocity and position weights (bbar None for a
    first-order method); e, ebar (S,): the embedded error weights (None without an embedded
    pair); e_aux (S,): DOP853's second (third-order) estimate; first_order: a first-order
    method (its last stage is f(t + h, y1)).
    """

    name: str
    c: np.ndarray
    a: np.ndarray
    node: np.ndarray
    nodes: np.ndarray
    b: np.ndarray
    bbar: np.ndarray | None
    e: np.ndarray | None
    ebar: np.ndarray | None
    e_aux: np.ndarray | None
    first_order: bool

    @property
    def stages(self) -> int:
        return len(self.c)


def _nodes(c) -> tuple[np.ndarray, np.ndarray]:
    nodes = np.array(sorted({float(x) for x in c} | {1.0}))
    node = np.array([int(np.flatnonzero(nodes == float(x))[0]) for x in c], dtype=np.int32)
    return node, nodes


def _plan(
    name: str,
    c: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    e: np.ndarray | None,
    *,
    bbar: np.ndarray | None = None,
    ebar: np.ndarray | None = None,
    e_aux: np.ndarray | None = None,
    first_order: bool = False,
) -> StagePlan:
    """The :class:`StagePlan` of nodes ``c``, coupling ``a`` and the weights, with the node
    indices and the distinct nodes of ``c``."""
    node, nodes = _nodes(c)
    return StagePlan(name, c, a, node, nodes, b, bbar, e, ebar, e_aux, first_order)


def _fold_nystrom(tab: NystromTableau) -> StagePlan:
    s = tab.stages
    root: list[int] = []
    for i in range(s):
        r = i
        for j in range(i):
            if tab.c[i] == tab.c[j] and np.array_equal(tab.a_bar[i], tab.a_bar[j]):
                r = root[j]
                break
        root.append(r)
    keep = [i for i in range(s) if root[i] == i]
    pos = {i: keep.index(root[i]) for i in range(s)}
    n = len(keep)

    def fold(w):
        if w is None:
            return None
        out = np.zeros(n)
        for i in range(s):
            out[pos[i]] += float(w[i])
        return out

    a = np.stack([fold(tab.a_bar[i]) for i in keep])
    c = np.array([float(tab.c[i]) for i in keep])
    return _plan(tab.name, c, a, fold(tab.b), fold(tab.e), bbar=fold(tab.bbar), ebar=fold(tab.ebar))


def _extend_rk(tab: RungeKuttaTableau) -> StagePlan:
    s = tab.stages
    a = np.zeros((s + 1, s + 1))
    a[:s, :s] = np.asarray(tab.a, float)
    a[s, :s] = np.asarray(tab.b, float)
    c = np.concatenate([np.asarray(tab.c, float), [1.0]])
    b = np.concatenate([np.asarray(tab.b, float), [0.0]])
    e_aux = None if tab.e_aux is None else np.asarray(tab.e_aux, float)
    return _plan(tab.name, c, a, b, np.asarray(tab.e, float), e_aux=e_aux, first_order=True)


@functools.cache
def _plan_cached(tab) -> StagePlan:
    if isinstance(tab, NystromTableau):
        return _fold_nystrom(tab)
    return _extend_rk(tab)


def plan_of_tableau(tab) -> StagePlan:
    """The :class:`StagePlan` of a tableau (cached; tableaux hash by identity)."""
    return _plan_cached(tab)


@jax.custom_batching.custom_vmap
def _materialise(k):
    """Keep a stage value as a value of its own in an unrolled step (perf-notes item 2: XLA
    CPU otherwise re-fuses the cheap part of every stage into each later stage).  The
    identity; under ``vmap`` it adds 0 x (the sum over every lane, non-finite values mapped to
    0), a reduction across the batch that the stage's consumers cannot fuse through, so the
    stage is computed once for all lanes and stored (measured 1.3-1.7x on DPRKN12 LEO
    batches)."""
    return k


@_materialise.def_vmap
def _materialise_vmap(axis_size, in_batched, k):
    (batched,) = in_batched
    if not batched:
        return k, False
    # nan_to_num: a lane that failed (NaN/inf) must not poison the others through the sum
    return k + 0.0 * jnp.nan_to_num(jnp.sum(k), nan=0.0, posinf=0.0, neginf=0.0), True


def _lincomb(coeffs, ks):
    """sum_j coeffs[j] ks[j] over the nonzero (static) coefficients; None when all vanish."""
    out = None
    for cj, kj in zip(coeffs, ks):
        cj = float(cj)
        if cj == 0.0:
            continue
        term = jax.tree_util.tree_map(functools.partial(jnp.multiply, cj), kj)
        out = term if out is None else jax.tree_util.tree_map(jnp.add, out, term)
    return out


def _unrolled(stage, y_of, plan: StagePlan, k0):
    """The stages as a Python loop with static coefficients (zero terms skipped): ``stage``
    is traced once per stage, and XLA fuses the whole step (the fast form for wide vmapped
    batches); returns the stage values as a list (:class:`StageValues`)."""
    ks = []
    for i in range(plan.stages):
        if i == 0 and k0 is not None:
            ks.append(k0)
            continue
        k = stage(i, y_of(i, _lincomb(plan.a[i, :i], ks)))
        ks.append(jax.tree_util.tree_map(_materialise, k))
    return StageValues(ks)


class StageValues:
    """The stage values of one step: a stacked pytree (leading stage axis; the loop form) or
    a list of per-stage pytrees (the unrolled form, whose weighted sums skip zero weights)."""

    def __init__(self, ks):
        self.ks = ks

    def weighted(self, w):
        """sum_j w[j] K_j (pytree like one stage's value)."""
        if not isinstance(self.ks, list):
            return weighted(w, self.ks)
        out = _lincomb(w, self.ks)
        if out is None:
            return jax.tree_util.tree_map(jnp.zeros_like, self.ks[0])
        return out

    def last(self):
        """The last stage's value."""
        if isinstance(self.ks, list):
            return self.ks[-1]
        return jax.tree_util.tree_map(lambda k: k[-1], self.ks)

    def part(self, j):
        """Element j of a tuple-valued stage value, for every stage."""
        if isinstance(self.ks, list):
            return StageValues([k[j] for k in self.ks])
        return StageValues(self.ks[j])

    def cols(self, sl):
        """A slice of the last axis of an array-valued stage value, for every stage."""
        if isinstance(self.ks, list):
            return StageValues([k[..., sl] for k in self.ks])
        return StageValues(self.ks[..., sl])


def _looped(stage, y_of, like, plan: StagePlan, k0):
    """The stages under ``lax.fori_loop`` (``stage`` traced once): stage i's input is
    ``y_of(i, sum_j a_ij K_j)``; the stage values are written into arrays with a leading
    stage axis, shaped like the pytree ``like``."""
    a = jnp.asarray(plan.a)
    n = plan.stages
    ks0 = jax.tree_util.tree_map(lambda x: jnp.zeros((n,) + jnp.shape(x), jnp.result_type(x, jnp.float64)), like)
    start = 0
    if k0 is not None:
        ks0 = jax.tree_util.tree_map(lambda ks, k: ks.at[0].set(k), ks0, k0)
        start = 1

    def body(i, ks):
        k = stage(i, y_of(i, weighted(a[i], ks)))
        return jax.tree_util.tree_map(lambda kk, new: kk.at[i].set(new), ks, k)

    return StageValues(jax.lax.fori_loop(start, n, body, ks0))


def weighted(w, ks):
    """sum_j w[j] ks[j] over the stage axis of every leaf of the pytree ``ks``.

    Written as a broadcast product and a sum (not a dot product): under ``vmap`` a
    batched ``dot_general`` runs as a separate, unvectorised kernel on XLA CPU."""
    w = jnp.asarray(w, jnp.float64)

    def one(k):
        return jnp.sum(jnp.reshape(w, (-1,) + (1,) * (k.ndim - 1)) * k, axis=0)

    return jax.tree_util.tree_map(one, ks)


def _axpy(y, alpha, x):
    return jax.tree_util.tree_map(lambda yy, xx: yy + alpha * xx, y, x)


def nystrom_stages(stage, q, p, h, plan: StagePlan, k0=None, unroll=False):
    """All stage values of a special RKN step: K (S, ...) per leaf.

    ``stage(i, q_i)``: the acceleration (pytree like ``q``) at stage i (node ``plan.c[i]``)
    for the stage position q_i = q + c_i h p + h^2 sum_j a_ij K_j.  ``q``, ``p``: pytrees of
    the same structure (positions, velocities).  ``k0``: stage 0's value when already known
    (first same as last), else it is evaluated.  Traces ``stage`` once under
    ``lax.fori_loop`` (``i`` traced); ``unroll=True``: a Python loop (``i`` a Python int),
    ``stage`` traced once per stage (a larger program that XLA CPU runs faster on wide
    vmapped batches).
    """
    if unroll:

        def y_of(i, s):
            ci = float(plan.c[i])
            qi = q if ci == 0.0 else _axpy(q, ci * h, p)
            return qi if s is None else _axpy(qi, h * h, s)

        return _unrolled(stage, y_of, plan, k0)
    c = jnp.asarray(plan.c)
    return _looped(stage, lambda i, s: _axpy(_axpy(q, c[i] * h, p), h * h, s), q, plan, k0)


def rk_stages(stage, y, h, plan: StagePlan, k0=None, unroll=False):
    """All stage derivatives of a first-order step: K (S, ...) per leaf (S counts the final
    stage f(t + h, y1) of the error estimate, ``plan.first_order``).

    ``stage(i, y_i)``: the derivative (pytree like ``y``) at stage i for
    y_i = y + h sum_j a_ij K_j.  ``k0``: stage 0's value when already known.  The final
    stage's input is y1 = y + h sum_j b_j K_j itself (its coupling row is b).  ``unroll``:
    as in :func:`nystrom_stages`.
    """
    if unroll:
        return _unrolled(stage, lambda i, s: y if s is None else _axpy(y, h, s), plan, k0)
    return _looped(stage, lambda i, s: _axpy(y, h, s), y, plan, k0)
