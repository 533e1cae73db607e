"""The reference as the TEAM guidance events see it (FRACAS GUIDM, TARMAT §5.4.9;
:mod:`fracas.team.guidance`): states and transitions between any two times
(:class:`ReferenceSpan`, from the STM file or integrated), the augmented transition with the
exact Gauss-Markov noise states, the targets' sensitivity Ψ, the thrust at a time and the
true process noise between two times."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from fracas.dynamics.parameters import get_values
from fracas.errors import ConfigError
from fracas.products import ReferenceTrajectory, chain, time_indices
from fracas.team.study import GuidanceSpec, Study
from fracas.team.transitions import EPS_T, interval_noise

__all__ = ["ReferenceSpan", "augment"]


class ReferenceSpan:
    """The reference at any times: states and transitions between two times (7-state Φ and
    Θ for the study's dynamic labels), from a reference product when it holds the times,
    else integrated in line (cached)."""

    def __init__(self, study: Study, product: ReferenceTrajectory | None = None) -> None:
        self.study = study
        self.product = product
        self._wanted: tuple[float, ...] = ()
        self.memo: dict[tuple, object] = {}  # Ψ, S and thrust levels, reused by budget runs

    def prefetch(self, times: Iterable[float]) -> None:
        """Integrate once over every time the guidance will ask for (in-line references)."""
        self._wanted = tuple(sorted(set(self._wanted) | {float(t) for t in times}))

    def _integrated(self, times: tuple[float, ...]) -> tuple:
        """One in-line integration (0, the prefetched times and ``times``), cached."""
        from fracas.team.reference import run_reference

        grid = getattr(self, "_grid", None)
        if grid is not None and all(np.min(np.abs(grid[0] - t)) < 1e-6 for t in times):
            return grid
        t_out = np.array(sorted(set((0.0,) + tuple(self._wanted) + tuple(float(t) for t in times))))
        traj, sens, status, failed = run_reference(self.study.problem, t_out, self.study.dynamic_labels)
        if status != 0:
            raise ConfigError(
                f"{self.study.source}: guidance: the reference ends before {failed / 86400.0:.6g} d "
                "(a guidance, cutoff or target time lies beyond the trajectory)"
            )
        self._grid = (t_out, np.asarray(traj.x), np.asarray(traj.primary), sens, self.study.problem.model.bodies)
        self._wanted = tuple(t_out)
        return self._grid

    def _from_product(self, times: list[float]) -> bool | None:
        if self.product is None:
            return None
        try:
            time_indices(self.product, list(times))
        except Exception:  # noqa: BLE001  (a time the file lacks: integrate instead)
            return None
        return True

    def state(self, t_s: float) -> tuple[np.ndarray, str]:
        """(7,) state relative to the central body and that body's name at t_s."""
        if self._from_product([t_s]):
            i = int(time_indices(self.product, [t_s])[0])
            return np.asarray(self.product.states[i], dtype=np.float64), self.product.primary[i]
        t_out, x, prim, _, bodies = self._integrated((float(t_s),))
        i = int(np.argmin(np.abs(t_out - t_s)))
        p = int(prim[i])
        return x[i].astype(np.float64), bodies[p] if 0 <= p < len(bodies) else ""

    def transition(self, t_to: float, t_from: float) -> tuple[np.ndarray, np.ndarray]:
        """Φ(t_to, t_from) (7, 7) and Θ(t_to, t_from) (7, n_dyn)."""
        n_dyn = len(self.study.dynamic_labels)
        if abs(t_to - t_from) < 1e-9:
            return np.eye(7), np.zeros((7, n_dyn))
        if self._from_product([t_from, t_to]):
            phi, theta = chain(self.product, [t_from, t_to])
            return np.asarray(phi[1]), np.asarray(theta[1])
        t_out, _, _, sens, _ = self._integrated((float(t_from), float(t_to)))
        i0 = int(np.argmin(np.abs(t_out - t_from)))
        i1 = int(np.argmin(np.abs(t_out - t_to)))
        stm = np.asarray(sens.stm)
        par = np.asarray(sens.par)
        phi = stm[i1] @ np.linalg.inv(stm[i0])
        theta = par[i1] - phi @ par[i0]
        return phi, theta


def augment(study: Study, phi7: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The augmented transition (n, n) of PROP eq. 3 from Φ (7, 7) and Θ (7, n_dyn)."""
    n, nx = study.layout.n, study.nx
    out = np.eye(n)
    out[:nx, :nx] = phi7[:nx, :nx]
    j = 0
    for i, d in enumerate(study.dynamic):
        if d:
            out[:nx, nx + i] = theta[:nx, j]
            j += 1
    return out


def _gm_blocks(
    study: Study, span: ReferenceSpan, t_to: float, t_from: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exact model's true-side (Gamma (nx, 3), E (3,), Q (nx + 3, nx + 3)) from t_from
    to t_to (fracas.team.gm_exact; ``study.gm_states``), memoized on the span."""
    from fracas.team.gm_exact import exact_noise

    key = ("gm", float(t_to), float(t_from), tuple(study.noise_sigma_true), tuple(study.noise_tau_true))
    if key not in span.memo:
        t = np.array([t_from, t_to], dtype=np.float64)
        x0, b0 = span.state(t_from)
        x1, b1 = span.state(t_to)
        ex = exact_noise(study, t, x0, np.array([x0, x1]), [b0, b1])
        g, e, q = (
            (ex.gamma_true, ex.E_true, ex.Q_true) if study.gencov else (ex.gamma_assumed, ex.E_assumed, ex.Q_assumed)
        )
        span.memo[key] = (g[1], e[1], q[1])
    return span.memo[key]


def _transition(study: Study, span: ReferenceSpan, t_to: float, t_from: float) -> np.ndarray:
    """The augmented transition (n, n) from t_from to t_to: PROP eq. 3, and with the exact
    Gauss-Markov model's noise states (``study.gm_states``) their true Gamma and E."""
    phi, theta = span.transition(t_to, t_from)
    out = augment(study, phi, theta)
    if study.gm_states and t_to > t_from:
        gam, e, _ = _gm_blocks(study, span, t_to, t_from)
        n = study.layout.n
        out[: study.nx, n - 3 :] = gam
        out[np.arange(n - 3, n), np.arange(n - 3, n)] = e
    return out


def _embed(study: Study, x: np.ndarray) -> np.ndarray:
    n = study.layout.n
    out = np.zeros((n, n))
    k = x.shape[0]
    out[:k, :k] = x
    return out


def _target_psi(study: Study, span: ReferenceSpan, g: GuidanceSpec, t_s: float) -> tuple[np.ndarray, str]:
    """Ψ (m, n) of g's targets with respect to the augmented state at t_s; the body used."""
    key = ("psi", g.name, g.target_time_s, t_s, tuple(g.targets), g.target_body)
    if key not in span.memo:
        a_t, body = _target_jacobian(study, span, g)
        span.memo[key] = (a_t @ _transition(study, span, g.target_time_s, t_s)[: study.nx, :], body)
    return span.memo[key]


def _target_jacobian(study: Study, span: ReferenceSpan, g: GuidanceSpec) -> tuple[np.ndarray, str]:
    """A_T = ∂T/∂X_f (m, nx) of g's targets at its target time (TARMAT, digest (G-2)) and the
    target body, memoized on the span."""
    from fracas.guidance.targets import target_jacobian

    key = ("a_t", g.name, g.target_time_s, tuple(g.targets), g.target_body)
    if key not in span.memo:
        x_f, body_f = span.state(g.target_time_s)
        body = g.target_body or body_f
        x_rel = np.array(x_f[:6], dtype=np.float64)
        if body != body_f:  # the target body's state relative to the central body (DE421)
            x_rel = x_rel - _relative_body_state(study, body, body_f, g.target_time_s)
        mu = float(np.asarray(get_values(study.problem.params, [f"mu[{body}]"], study.problem.model))[0])
        a_t = np.asarray(target_jacobian(tuple(g.targets), x_rel, float(g.target_time_s), mu))
        span.memo[key] = (np.asarray(a_t[:, : study.nx], dtype=np.float64), body)
    return span.memo[key]


def _target_noise(study: Study, span: ReferenceSpan, g: GuidanceSpec, t_s: float) -> np.ndarray:
    """The true process noise from t_s (the event's cutoff) to g's target time mapped to its
    targets: A_T Q(t_s → t_f) A_Tᵀ (m, m), Q the state block of :func:`_noise_between` (the
    same noise model as the control covariance's).  Zero without process noise or when the
    target time is not after t_s.

    GUIDM maps the control covariance at the cutoff to the target (P_T = Ψ P_c Ψᵀ, digest
    (G-8)), which leaves out every unmodeled acceleration after the cutoff; the dispersion
    the spacecraft actually arrives with is Ψ P_c Ψᵀ + A_T Q(t_c → t_f) A_Tᵀ, the control
    covariance propagated to the target time with its noise (what TSIM flies)."""
    a_t, _ = _target_jacobian(study, span, g)
    t_f = float(g.target_time_s)
    if not study.has_process_noise or t_f <= t_s + EPS_T:
        return np.zeros((a_t.shape[0], a_t.shape[0]))
    key = ("noise", float(t_s), t_f, *_noise_settings(study))
    if key not in span.memo:
        span.memo[key] = _noise_between(study, span, float(t_s), t_f)
    q = np.asarray(span.memo[key])[: study.nx, : study.nx]
    out = a_t @ q @ a_t.T
    return 0.5 * (out + out.T)


def _noise_settings(study: Study) -> tuple:
    """What :func:`_noise_between` depends on besides the times (a memo key: the error
    budget's single-source runs change the true noise levels)."""
    return (
        study.noise_model,
        study.gencov,
        study.gm_states,
        tuple(np.ravel(study.noise_sigma_true)),
        tuple(np.ravel(study.noise_tau_true)),
        tuple(np.ravel(study.noise_sigma_assumed)),
        tuple(np.ravel(study.noise_tau_assumed)),
        float(study.white_q_true),
        float(study.white_q_assumed),
        study.white_direction_true,
        study.white_direction_assumed,
    )


def _relative_body_state(study: Study, body: str, centre: str, t_s: float) -> np.ndarray:
    """(6,) state of ``body`` relative to ``centre`` at t_s (s from the epoch), ICRF, DE421.

    The targets are functions of the spacecraft's state relative to the target body; that
    body's own motion does not depend on the spacecraft, so A_T is unchanged."""
    from fracas.constants import DAY_S
    from fracas.dynamics.ephemeris import body_states, build_ephemeris

    et = float(study.problem.epoch_et_s) + float(t_s)
    names = sorted({body, centre} - {"sun"})
    table = build_ephemeris(names, et - DAY_S, et + DAY_S, margin_s=DAY_S)
    pos, vel = (np.asarray(a) for a in body_states(table, et))
    helio = {b: np.concatenate([pos[i], vel[i]]) for i, b in enumerate(names)}
    helio["sun"] = np.zeros(6)
    return helio[body] - helio[centre]


def _thrust_at(study: Study, t_s: float, x: np.ndarray, body: str) -> tuple[float, float]:
    """(thrust acceleration km/s², thrust kg km/s²) at t_s from the mass rate: T = −c ṁ."""
    from fracas.integrate.variational import state_derivative

    pr = study.problem
    c = float(np.asarray(get_values(pr.params, ["exhaust_velocity_km_s"], pr.model))[0])
    prim = pr.model.bodies.index(body)
    xd = np.asarray(state_derivative(pr.model, pr.params, pr.ephem, pr.epoch_et_s, float(t_s), x, prim))
    thrust = -c * float(xd[6])
    return thrust / float(x[6]), thrust


def _thrust_ends(study: Study, span: ReferenceSpan, t_i: float, t_c: float) -> tuple:
    """(x_i, x_c, (acceleration, thrust) just after t_i, the same just before t_c) of a
    low-thrust correction from t_i to its cutoff t_c (:func:`_thrust_at`), memoized on the span."""
    key = ("thrust", t_i, t_c)
    if key not in span.memo:
        x_i, b_i = span.state(t_i)
        x_c, b_c = span.state(t_c)
        span.memo[key] = (
            x_i,
            x_c,
            _thrust_at(study, t_i + EPS_T, x_i, b_i),
            _thrust_at(study, t_c - EPS_T, x_c, b_c),
        )
    return span.memo[key]


def _noise_between(study: Study, span: ReferenceSpan, t_a: float, t_b: float) -> np.ndarray:
    """The true process noise accumulated from t_a to t_b, at t_b, by the study's noise model
    (the control covariance's): with the exact model's noise states (``study.gm_states``)
    the exact Q (n, n) on the state and noise-state blocks; the fixed cells
    (``noise_model = "grid"``) Q (nx, nx) of the cells between t_a and t_b
    (:func:`fracas.team.transitions.grid_noise`, the cell that straddles t_a cut there);
    otherwise DYNO's Q̃ (nx, nx) split at the thrust switches; each plus the white noise."""
    nx = study.nx
    if study.gm_states:
        n = study.layout.n
        out = np.zeros((n, n))
        if t_b > t_a:
            _, _, q = _gm_blocks(study, span, t_b, t_a)
            sel = np.r_[np.arange(nx), np.arange(n - 3, n)]
            out[np.ix_(sel, sel)] = q
            if study.has_white_noise:
                from fracas.team.transitions import white_noise

                x0, _ = span.state(t_a)
                wa, wt = white_noise(study, np.array([t_a, t_b]), x0)
                out[:nx, :nx] += (wt if study.gencov else wa)[1]
        return out
    if not study.has_process_noise or t_b <= t_a:
        return np.zeros((nx, nx))
    if study.noise_model == "grid":
        from fracas.team.transitions import grid_noise

        x_a, _ = span.state(t_a)
        _, qt = grid_noise(study, np.array([t_a, t_b]), x_a, span.product)  # the control's Qt
        return np.asarray(qt)[1]
    cuts = [t_a] + [s for s in study.thrust_switches_s if t_a + EPS_T < s < t_b - EPS_T] + [t_b]
    t = np.array(cuts)
    states, prim, phis = [], [], [np.eye(7)]
    for i, ti in enumerate(t):
        x, b = span.state(ti)
        states.append(x)
        prim.append(b)
        if i:
            phis.append(span.transition(ti, t[i - 1])[0])
    _, qt = interval_noise(study, t, np.array(states), prim, np.array(phis))
    q = np.zeros((nx, nx))
    for i in range(1, len(t)):
        ph = phis[i][:nx, :nx]
        q = ph @ q @ ph.T + qt[i]
    return q
