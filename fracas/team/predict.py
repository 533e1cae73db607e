"""Prediction events (FRACAS PRED): map the knowledge ahead to a later time without changing the run.

When the target time (and every thrust switch on the way) is a reference time, the stored
transitions are composed; otherwise the reference is integrated afresh from the stored
state at the event time (the STM file's trajectory deck when the study reads one), with breaks at the thrust switches in
between so DYNO's Q̃ never straddles one; assumed and true covariances are mapped with
PROP eq. 1 over each piece.  With the fixed-cell noise model (``errcon.process_noise =
"grid"``, fracas.team.transitions.grid_noise) the noise comes from the study's noise cells,
the first one clipped to start at the event time.
"""

from __future__ import annotations

import numpy as np

from fracas.constants import body_names_at
from fracas.filters import covariance as cov
from fracas.integrate.propagate import propagate_with_sensitivities
from fracas.status import RunStatus
from fracas.team.reference import Reference
from fracas.team.transitions import augmented_transitions, grid_noise, interval_noise

__all__ = ["predictions", "predict_from"]


def predict_from(res, k: int, t_to: float):
    """(P_assumed, P_true or None, status) predicted from schedule index k to ``t_to`` (s).

    A prediction whose integration stops before ``t_to`` returns NaN matrices and
    ``RunStatus.OUTSIDE_TRAJECTORY`` (the caller reports it; nothing raises here).
    """
    study, ref = res.study, res.ref
    pr = study.problem
    t_k = float(res.times_s[k])
    mids = sorted(t for t in set(study.thrust_switches_s) if t_k + 1e-3 < t < t_to - 1e-3)
    t_out = np.array([t_k] + mids + [t_to])
    labels = study.dynamic_labels
    on_ref = [int(np.argmin(np.abs(ref.times_s - t))) for t in t_out]
    if all(abs(ref.times_s[j] - t) < 1e-6 for j, t in zip(on_ref, t_out)):
        # every piece ends on a reference time: compose the stored transitions (no integration)
        phi = np.broadcast_to(np.eye(7), (len(t_out), 7, 7)).copy()
        theta = np.zeros((len(t_out), 7, ref.theta.shape[2]))
        for i in range(1, len(t_out)):
            for j in range(on_ref[i - 1] + 1, on_ref[i] + 1):
                phi[i] = ref.phi[j] @ phi[i]
                theta[i] = ref.phi[j] @ theta[i] + ref.theta[j]
        sub = Reference(t_out, ref.states[on_ref], [ref.primary[j] for j in on_ref], phi, theta, labels, "reference")
        prim = sub.primary
    else:
        traj, sens = propagate_with_sensitivities(
            pr.model, pr.params, pr.ephem, pr.epoch_et_s, ref.states[k], t_out, labels
        )
        phi = np.array(sens.stm_step)
        if not np.all(np.isfinite(phi)):
            n = study.layout.n
            nan = np.full((n, n), np.nan)
            return nan, (nan.copy() if res.Pt_plus is not None else None), RunStatus.OUTSIDE_TRAJECTORY
        phi[0] = np.eye(7)
        theta = np.array(sens.par_step)
        theta[0] = 0.0
        prim = body_names_at(pr.model.bodies, np.asarray(traj.primary))
        sub = Reference(t_out, np.array(traj.x), prim, phi, theta, labels, "prediction")
    phis = augmented_transitions(study, sub)
    if getattr(res, "noise_states", False) and study.propagation == "phi":  # exact GM: carry the noise states
        return _predict_exact(res, k, t_out, sub, phis, prim)
    if study.noise_model == "interval":
        Qa, Qt = interval_noise(study, t_out, sub.states, prim, phi)
    else:  # the fixed noise cells, clipped to start at t_k
        Qa, Qt = grid_noise(study, t_out, ref.states[k], ref.product)  # read from the reference's product
    n = study.layout.n  # PDOT's noise states (appended last) are dropped: DYNO's Q̃ stands for them
    Pa = res.Pa_plus[k][:n, :n]
    Pt = res.Pt_plus[k][:n, :n] if res.Pt_plus is not None else None
    for j in range(1, len(t_out)):
        Pa = np.asarray(cov.time_update(Pa, phis[j], Qa[j]))
        if Pt is not None:
            Pt = np.asarray(cov.time_update(Pt, phis[j], Qt[j]))
    return Pa, Pt, RunStatus.OK


def _predict_exact(res, k: int, t_out: np.ndarray, sub, phis: np.ndarray, prim):
    """The prediction with the exact model's noise states (fracas.team.gm_exact): the
    covariance over n + 3 states mapped with the exact Gamma, E and Q from t_k; returns the
    n x n blocks (the noise states are not reported in predictions)."""
    from fracas.team.gm_exact import augment_noise, augment_transitions, exact_noise
    from fracas.team.transitions import white_noise

    study = res.study
    nx, n = study.nx, study.layout.n
    ex = exact_noise(study, t_out, sub.states[0], sub.states, list(prim))
    if not (np.all(np.isfinite(ex.gamma_assumed)) and np.all(np.isfinite(ex.Q_assumed))):
        nan = np.full((n, n), np.nan)  # the integration through the pieces stopped
        return nan, (nan.copy() if res.Pt_plus is not None else None), RunStatus.OUTSIDE_TRAJECTORY
    zero = np.zeros((len(t_out), nx, nx))
    wa, wt = white_noise(study, t_out, sub.states[0]) if study.has_white_noise else (zero, zero)

    def mapped(P, gam, E, Q, W):
        ph, Qf = augment_transitions(phis, gam, E, nx), augment_noise(Q, W + zero, n)
        for j in range(1, len(t_out)):
            P = np.asarray(cov.time_update(P, ph[j], Qf[j]))
        return P

    Pa = mapped(res.Pa_plus[k], ex.gamma_assumed, ex.E_assumed, ex.Q_assumed, wa)
    Pt = None if res.Pt_plus is None else mapped(res.Pt_plus[k], ex.gamma_true, ex.E_true, ex.Q_true, wt)
    return Pa[:n, :n], (Pt[:n, :n] if Pt is not None else None), RunStatus.OK


def predictions(res):
    """Every prediction event of the schedule: ({k: [(t_to_s, P_assumed, P_true), ...]},
    {k: [status, ...]})."""
    out, status = {}, {}
    for k, targets in res.study.schedule.predict_to_s.items():
        got = [predict_from(res, k, t) for t in targets]
        out[k] = [(t, Pa, Pt) for t, (Pa, Pt, _) in zip(targets, got)]
        status[k] = [int(s) for _, _, s in got]
    return out, status
