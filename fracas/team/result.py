"""The result of a TEAM run: the engine's covariance history (:class:`TeamResult`), its
checks, and the :class:`~fracas.products.TeamProduct` that leaves the core.

``finish`` runs what follows the filter in both PHI and PDOT modes: the positive-
definiteness watch and the prediction events (FRACAS PRED); ``team_product`` gathers the
history with its labels, eigenvector events (SETEVN) and measurement log into the frozen
product that :mod:`fracas.io.team_results` writes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from fracas import _jax  # noqa: F401
from fracas.filters import covariance as cov
from fracas.products import ControlHistory, CovarianceHistory, EigenEvents, MeasurementLog, Prediction, TeamProduct
from fracas.status import RunStatus
from fracas.team.eigen import eigen_summary
from fracas.team.measure import MeasurementSet
from fracas.team.predict import predictions
from fracas.team.reference import Reference
from fracas.team.study import NOISE_STATE_LABELS, Study

__all__ = [
    "TeamResult",
    "NOISE_STATE_LABELS",
    "NOISE_STATE_UNITS",
    "EIGEN_EVENTS",
    "psd_problems",
    "event_status",
    "finish",
    "team_product",
]

NOISE_STATE_UNITS = ["1", "rad", "rad"]
EIGEN_EVENTS = frozenset({"eigenvector", "thrust_on", "thrust_off", "final"})  # events that print eigenvectors


@dataclass
class TeamResult:
    """The covariance history of a study (assumed and, with generalized covariance, true).

    P_minus / P_plus (K, n, n): before / after the event at each schedule time; Q_assumed,
    Q_true (K, nx, nx): effective process noise over the interval ending at each time;
    innovation_sigma (K, m): sqrt(diag J) of the assumed filter; predictions: per schedule
    index, list of (t_to_s, P_assumed, P_true); psd: list of (k, event, which, min eig).
    """

    study: Study
    ref: Reference
    meas: MeasurementSet
    Pa_minus: np.ndarray
    Pa_plus: np.ndarray
    Pt_minus: np.ndarray | None
    Pt_plus: np.ndarray | None
    Q_assumed: np.ndarray
    Q_true: np.ndarray
    innovation_sigma: np.ndarray
    predictions: dict[int, list[tuple[float, np.ndarray, np.ndarray | None]]] = field(default_factory=dict)
    psd_problems: list[tuple[int, str, str, float]] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    noise_states: bool = False  # PDOT: the three Gauss-Markov states follow the parameters
    prediction_status: dict[int, list[int]] = field(default_factory=dict)
    control: np.ndarray | None = None  # (K, n, n) control covariance after each event (guidance)
    control_epoch: np.ndarray | None = None  # (K,) schedule index of its last reset
    guidance: list = field(default_factory=list)  # fracas.team.guidance.GuidanceOutcome, in time order
    budget: object | None = None  # fracas.team.budget.ErrorBudget

    @property
    def status(self) -> RunStatus:
        """OK; NONFINITE_COVARIANCE or NOT_POSITIVE_DEFINITE when the history has such
        events (listed in ``psd_problems``); OUTSIDE_TRAJECTORY when the reference or a
        prediction ran off the trajectory."""
        if self.ref.status != RunStatus.OK:
            return RunStatus(self.ref.status)
        if any(s for lst in self.prediction_status.values() for s in lst):
            return RunStatus.OUTSIDE_TRAJECTORY
        if self.psd_problems or not np.all(np.isfinite(self.Pa_plus)):
            nonfinite = any(not np.isfinite(e) for _, _, _, e in self.psd_problems) or not np.all(
                np.isfinite(self.Pa_plus)
            )
            if self.Pt_plus is not None and not np.all(np.isfinite(self.Pt_plus)):
                nonfinite = True
            return RunStatus.NONFINITE_COVARIANCE if nonfinite else RunStatus.NOT_POSITIVE_DEFINITE
        return RunStatus.OK

    @property
    def times_s(self) -> np.ndarray:
        return self.study.schedule.times_s

    @property
    def labels(self) -> list[str]:
        """Row/column labels of the covariances: state, parameters [, PDOT noise states]."""
        st = self.study
        return st.state_labels + st.labels + (NOISE_STATE_LABELS if self.noise_states else [])

    @property
    def units(self) -> list[str]:
        st = self.study
        return st.state_units + st.units + (NOISE_STATE_UNITS if self.noise_states else [])

    @property
    def roles(self) -> list[str]:
        st = self.study
        return ["state"] * st.nx + st.roles + (["noise_state"] * 3 if self.noise_states else [])


_psd_batch = jax.jit(jax.vmap(cov.psd_check))


def psd_problems(study: Study, P: np.ndarray, which: str) -> list[tuple[int, str, str, float]]:
    """Schedule indices where a covariance lost positive semi-definiteness or is not finite
    (:func:`fracas.filters.covariance.psd_check` on every event): (k, event, which, smallest
    eigenvalue in the covariance's mixed units).

    Fast path for the usual healthy history: psd_check's scale-free criterion (smallest
    eigenvalue of D^-1/2 P D^-1/2 >= -PSD_TOLERANCE) holds exactly when D^-1/2 P D^-1/2 +
    PSD_TOLERANCE I has a Cholesky factor, which numpy does for the whole history in a few ms
    (JAX's batched eigendecomposition on the CPU takes ~0.1 s); only a failing history goes
    through psd_check event by event.
    """
    d = np.einsum("kii->ki", P)
    if np.all(np.isfinite(P)) and np.all(d >= -cov.PSD_TOLERANCE * np.max(np.abs(d), axis=1, keepdims=True)):
        sc = np.sqrt(np.where(d > 0, d, 1.0))
        S = P / sc[:, :, None] / sc[:, None, :]
        try:
            np.linalg.cholesky(0.5 * (S + S.transpose(0, 2, 1)) + cov.PSD_TOLERANCE * np.eye(P.shape[1]))
            return []
        except np.linalg.LinAlgError:
            pass
    min_eig, ok = (np.asarray(a) for a in _psd_batch(jnp.asarray(P)))
    return [(int(k), study.schedule.primary_type(int(k)), which, float(min_eig[k])) for k in np.nonzero(~ok)[0]]


def event_status(P: np.ndarray, problems: list[tuple[int, str, str, float]], which: str) -> np.ndarray:
    """(K,) int64 :class:`~fracas.status.RunStatus` of each event's covariance ``P`` (K, n, n):
    NONFINITE_COVARIANCE where P[k] has a NaN/inf entry, NOT_POSITIVE_DEFINITE at the other
    indices :func:`psd_problems` listed for history ``which`` ("assumed" or "true"), OK
    elsewhere."""
    out = np.full(P.shape[0], int(RunStatus.OK), dtype=np.int64)
    out[[k for k, _, w, _ in problems if w == which]] = int(RunStatus.NOT_POSITIVE_DEFINITE)
    out[~np.all(np.isfinite(P.reshape(P.shape[0], -1)), axis=1)] = int(RunStatus.NONFINITE_COVARIANCE)
    return out


def finish(res: TeamResult, tm: dict) -> None:
    """Positive-definiteness checks and prediction events (shared by PHI and PDOT)."""
    study = res.study
    res.psd_problems = psd_problems(study, res.Pa_plus, "assumed")
    if res.Pt_plus is not None:
        res.psd_problems += psd_problems(study, res.Pt_plus, "true")
    t3 = time.perf_counter()
    if study.schedule.predict_to_s:
        res.predictions, res.prediction_status = predictions(res)
    tm["predictions_s"] = time.perf_counter() - t3
    res.timing.update(tm)


def _eigen_events(P: np.ndarray, events: list[list[str]]) -> EigenEvents:
    ev = [k for k, e in enumerate(events) if EIGEN_EVENTS & set(e)]
    es = [eigen_summary(P[k]) for k in ev]
    n = P.shape[1]
    if not es:
        z3, z33 = np.zeros((0, 3)), np.zeros((0, 3, 3))
        return EigenEvents(np.array(ev, dtype=np.int64), z3, z33, z3.copy(), z33.copy(), np.zeros((0, n, n)))
    return EigenEvents(
        np.array(ev, dtype=np.int64),
        np.array([e.pos_eigval for e in es]),
        np.array([e.pos_eigvec for e in es]),
        np.array([e.vel_eigval for e in es]),
        np.array([e.vel_eigvec for e in es]),
        np.array([e.corr for e in es]),
    )


def _history(Pm, Pp, Q, P0, events, status) -> CovarianceHistory:
    with np.errstate(invalid="ignore"):
        sig = np.sqrt(np.clip(np.einsum("kii->ki", Pp), 0, None))
        sig0 = np.sqrt(np.clip(np.diag(P0), 0, None))
    return CovarianceHistory(Pm, Pp, Q, sig, sig0, _eigen_events(Pp, events), status)


def _initial_cov(st: Study, n: int, P0: np.ndarray) -> np.ndarray:
    """A history's a priori over its n states (PDOT: the noise states start stationary at their sigma)."""
    if n == P0.shape[0]:
        return P0
    out = np.zeros((n, n))  # PDOT: the noise states start stationary at their sigma
    out[: P0.shape[0], : P0.shape[0]] = P0
    sig = st.noise_sigma_assumed if P0 is st.P0_assumed else st.noise_sigma_true
    out[P0.shape[0] :, P0.shape[0] :] = np.diag(sig**2)
    return out


def _measurement_log(res: TeamResult) -> MeasurementLog:
    """Every observation of the run, used or skipped, with its innovation sigma."""
    recs = res.meas.records
    return MeasurementLog(
        index=np.array([r.k for r in recs], dtype=np.int64),
        tracking=np.array([r.tracking for r in recs], dtype=np.int64),
        kind=[r.kind for r in recs],
        stations=["+".join(r.stations) for r in recs],
        value=np.array([r.value for r in recs], dtype=np.float64),
        elevation_deg=np.array([r.elevation_deg for r in recs], dtype=np.float64),
        used=np.array([r.used for r in recs], dtype=bool),
        sigma=np.array([r.sigma for r in recs], dtype=np.float64),
        innovation_sigma=np.array(
            [res.innovation_sigma[r.k, r.row] if r.used else np.nan for r in recs], dtype=np.float64
        ),
    )


def _prediction_list(res: TeamResult) -> list[Prediction]:
    """The prediction events (PRED) in schedule order, each with its status."""
    preds = []
    for k, lst in sorted(res.predictions.items()):
        stat = res.prediction_status.get(k, [0] * len(lst))
        for (t_to, Pa, Pt), s in zip(lst, stat):
            preds.append(Prediction(int(k), float(res.times_s[k]), float(t_to), Pa, Pt, int(s)))
    return preds


def _settings(res: TeamResult, reference_source: str, settings: dict | None) -> dict:
    """The product's settings: the filter's, ``settings`` merged in, then the process noise's."""
    st = res.study
    sett = {
        "filter": st.filter_kind,
        "propagation": st.propagation,
        "square_root": bool(st.square_root),
        "generalized_covariance": bool(st.gencov),
        "reference": reference_source,
        "min_elevation_deg": float(st.min_elevation_deg),
    }
    if st.guidance:
        sett["guidance_model"] = st.guidance_model
    sett.update(settings or {})
    from fracas.team.transitions import noise_settings

    sett.update(noise_settings(st, res.ref))
    if sett.get("process_noise") == "exact" and st.has_noise:  # the exact model's pieces (issue 24)
        from fracas.filters.gauss_markov import GM_NODES
        from fracas.team.gm_exact import piece_step

        sett["gm_piece_step_s"] = float(piece_step(st, res.ref.states, res.ref.primary))
        sett["gm_nodes_per_piece"] = int(GM_NODES)
    return sett


def _control_history(res: TeamResult) -> ControlHistory | None:
    """The guidance's control covariance history, or None without guidance."""
    if res.control is None:
        return None
    st = res.study
    pc0 = st.P0_control if st.P0_control is not None else st.P0_true
    if res.control.shape[-1] > pc0.shape[0]:  # the exact model's noise states: control[0] is its a priori
        pc0 = res.control[0]
    sg = np.sqrt(np.clip(np.diagonal(res.control, axis1=1, axis2=2), 0.0, None))
    return ControlHistory(res.control, sg, np.asarray(res.control_epoch, dtype=np.int64), np.asarray(pc0))


def team_product(
    res: TeamResult, *, reference_source: str, settings: dict | None = None, provenance: dict | None = None
) -> TeamProduct:
    """The frozen, labelled :class:`~fracas.products.TeamProduct` of a run.

    ``settings``: extra descriptive entries (the print options, the trajectory deck's path
    and hash) merged into the product's settings; ``provenance``: deck text, path, versions.
    """
    st = res.study
    events = st.schedule.events
    n = res.Pa_plus.shape[1]
    sa = event_status(res.Pa_plus, res.psd_problems, "assumed")
    assumed = _history(res.Pa_minus, res.Pa_plus, res.Q_assumed, _initial_cov(st, n, st.P0_assumed), events, sa)
    true = None
    if res.Pt_plus is not None:
        stt = event_status(res.Pt_plus, res.psd_problems, "true")
        true = _history(res.Pt_minus, res.Pt_plus, res.Q_true, _initial_cov(st, n, st.P0_true), events, stt)
    log = _measurement_log(res)
    preds = _prediction_list(res)
    sett = _settings(res, reference_source, settings)
    control = _control_history(res)
    return TeamProduct(
        title=st.title,
        source=st.source,
        epoch_et_s=float(st.problem.epoch_et_s),
        times_s=res.times_s,
        event_types=["+".join(e) for e in events],
        states=res.ref.states,
        primary=list(res.ref.primary),
        labels=res.labels,
        units=res.units,
        roles=res.roles,
        n_state=st.nx,
        assumed=assumed,
        true=true,
        measurements=log,
        tracking=[(t.kind, "+".join(t.stations)) for t in st.tracking],
        predictions=preds,
        psd_problems=list(res.psd_problems),
        punch_indices=[k for k, e in enumerate(events) if "punch" in e],
        status=int(res.status),
        settings=sett,
        timing=dict(res.timing),
        provenance=dict(provenance or {}),
        guidance=list(res.guidance),
        control=control,
        budget=res.budget,
    )
