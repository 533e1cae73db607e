"""The TEAM executive: covariances through the event schedule (FRACAS TEAM, COVP, PROP, MEAS, FILTER).

The inputs of every event are assembled first (transition matrices, effective process
noise, observation matrices: :mod:`fracas.team.transitions`, :mod:`fracas.team.measure`),
then one jitted ``lax.scan`` runs the filter algebra of :mod:`fracas.filters` over the
whole schedule (:mod:`fracas.team.scan`): a time update to the event time (PROP eqs. 1-16
with DYNO's Q̃), then a measurement update (FILTER) whose gain comes from the assumed
covariance (KSGAIN, WLSGAN or a user gain) and is applied to the true covariance too
(generalized covariance).  Non-measurement events have zero H rows, which leave the
covariances unchanged.  PDOT mode (:mod:`fracas.team.pdot`) integrates the covariance
differential equations with the Gauss-Markov noise states augmented (DERY) instead of
mapping with transition matrices.  Eigenvector, prediction and punch events are evaluated
afterwards from the history (:mod:`fracas.team.result`).

The core of TEAM: it receives a :class:`~fracas.team.study.Study` and a
:class:`~fracas.team.reference.Reference` (arrays in canonical units) and returns a
:class:`~fracas.team.result.TeamResult` whose ``status`` says whether the run is sound;
it reads no deck or file.
"""

from __future__ import annotations

import time

import numpy as np

from fracas.filters.covariance import Layout
from fracas.team.gm_exact import (
    augment_noise,
    augment_transitions,
    augmented_P0,
    augmented_view,
    exact_noise,
    pad_H,
    uses_exact,
)
from fracas.team.measure import assemble_measurements
from fracas.team.pdot import run_pdot
from fracas.team.reference import Reference
from fracas.team.result import TeamResult, finish, psd_problems
from fracas.team.scan import run_filter
from fracas.team.study import Study
from fracas.team.transitions import (
    EPS_T,
    augmented_transitions,
    interval_noise,
    process_noise,
    theta_columns,
    white_noise,
)

__all__ = [
    "TeamResult",
    "run_study",
    "process_noise",
    "augmented_transitions",
    "interval_noise",
    "theta_columns",
    "psd_problems",
    "run_filter",
    "EPS_T",
]


def exact_inputs(study: Study, ref: Reference) -> dict:
    """The exact Gauss-Markov model's filter inputs (fracas.team.gm_exact): transitions and
    noise over n + 3 states, the expanded a priori and H, and the x-block noise for the
    results file (Q_assumed / Q_true, (K, nx, nx))."""
    t = np.asarray(ref.times_s, np.float64)
    nx, n = study.nx, study.layout.n
    ex = exact_noise(study, t, np.asarray(ref.states)[0], ref.states, ref.primary)
    wa, wt = white_noise(study, t, np.asarray(ref.states)[0]) if study.has_white_noise else (0.0, 0.0)
    zero = np.zeros((len(t), nx, nx))
    wa, wt = wa + zero, wt + zero
    phi_n = augmented_transitions(study, ref)
    phi_a = augment_transitions(phi_n, ex.gamma_assumed, ex.E_assumed, nx)
    same = np.array_equal(study.noise_tau_assumed, study.noise_tau_true) or not study.gencov
    phi_t = None if same else augment_transitions(phi_n, ex.gamma_true, ex.E_true, nx)
    L = study.layout
    return {
        "phi": phi_a,
        "Qa": augment_noise(ex.Q_assumed, wa, n),
        "Qt": augment_noise(ex.Q_true, wt, n),
        "Qa_x": ex.Q_assumed[:, :nx, :nx] + wa,
        "Qt_x": ex.Q_true[:, :nx, :nx] + wt,
        "augmented": {
            "layout": Layout(L.nx, L.ns, L.nu, L.nv, L.nw + 3),
            "P0_assumed": augmented_P0(study, 0),
            "P0_true": augmented_P0(study, 1),
            "phi_true": phi_t,
        },
        "pieces": ex.pieces,
        "piece_step_s": ex.piece_step_s,
    }


def _run_exact(study: Study, ref: Reference, meas, tm: dict, t1: float, stage, product=None) -> TeamResult:
    """The PHI run with the noise states augmented (exact Gauss-Markov thrust noise).

    Guidance events and the error budget run on the study's augmented view
    (fracas.team.gm_exact.augmented_view): their n x n algebra then carries the noise
    states, with the exact Gamma, E and Q between any two times (fracas.team.guidance)."""
    got = exact_inputs(study, ref)
    view = augmented_view(study, got["augmented"]["P0_assumed"], got["augmented"]["P0_true"])
    phi_t = got["augmented"]["phi_true"]
    aug = {"H": pad_H(meas.H), "phi_true": phi_t}
    tm["noise_transitions_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()

    def filt(xa, xt, host=True):
        return run_filter(view, got["phi"], got["Qa"], got["Qt"], meas, xa, xt, host=host, augmented=aug)

    grun = span = None
    if study.guidance:
        from fracas.team.guidance import ReferenceSpan, run_guidance

        span = ReferenceSpan(view, product if product is not None else getattr(ref, "product", None))
        stage("guidance events")
        grun = run_guidance(view, got["phi"] if phi_t is None else phi_t, got["Qt"], filt, span)
        outs = grun.outs
    else:
        outs = filt(None, None)
    Pa_m, Pa_p, Pt_m, Pt_p, sig = outs
    tm["filter_s"] = time.perf_counter() - t2
    tm["gm_pieces"] = got["pieces"]
    res = TeamResult(
        study,
        ref,
        meas,
        Pa_m,
        Pa_p,
        Pt_m if study.gencov else None,
        Pt_p if study.gencov else None,
        got["Qa_x"],
        got["Qt_x"],
        sig,
        noise_states=True,
    )
    if grun is not None:
        res.control, res.control_epoch, res.guidance = grun.control, grun.control_epoch, grun.outcomes
    if study.budget:
        from fracas.team.budget import error_budget

        stage("error budget")
        t3 = time.perf_counter()
        res.budget = error_budget(view, got["phi"], got["Qa"], got["Qt"], meas, outs, grun, span, augmented=aug)
        tm["budget_s"] = time.perf_counter() - t3
    return res


def run_study(study: Study, ref: Reference, progress=None, product=None) -> TeamResult:
    """The whole TEAM run on a prepared study and reference (PHI or PDOT propagation).

    Guidance events (``study.guidance``, PHI only) run after a first filter pass and feed
    their execution errors back into it (:mod:`fracas.team.guidance`); ``product``: the
    reference product (STM file contents) the study's reference came from, used for the
    guidance's transitions to cutoff and target times (None: integrated)."""
    stage = progress or (lambda _t: None)
    tm = {}
    t0 = time.perf_counter()
    stage("assembling observation matrices")
    meas = assemble_measurements(study, ref)
    tm["measurements_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    if study.propagation == "pdot":
        stage("integrating the covariance equations (PDOT)")
        res = run_pdot(study, ref, meas)
        res.timing.update(tm)
        return res
    stage("process noise and transitions")
    if uses_exact(study):
        res = _run_exact(study, ref, meas, tm, t1, stage, product)
        finish(res, tm)
        return res
    Qa, Qt = process_noise(study, ref)
    phi_aug = augmented_transitions(study, ref)
    tm["noise_transitions_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    stage("filtering")
    grun = span = None
    if study.guidance:
        from fracas.team.guidance import ReferenceSpan, run_guidance

        span = ReferenceSpan(study, product if product is not None else getattr(ref, "product", None))

        def filt(xa, xt):
            return run_filter(study, phi_aug, Qa, Qt, meas, xa, xt)

        stage("guidance events")
        grun = run_guidance(study, phi_aug, Qt, filt, span)
        outs = grun.outs
    else:
        outs = run_filter(study, phi_aug, Qa, Qt, meas)
    Pa_m, Pa_p, Pt_m, Pt_p, sig = outs
    tm["filter_s"] = time.perf_counter() - t2
    res = TeamResult(
        study, ref, meas, Pa_m, Pa_p, Pt_m if study.gencov else None, Pt_p if study.gencov else None, Qa, Qt, sig
    )
    if grun is not None:
        res.control, res.control_epoch, res.guidance = grun.control, grun.control_epoch, grun.outcomes
    if study.budget:
        from fracas.team.budget import error_budget

        stage("error budget")
        t3 = time.perf_counter()
        res.budget = error_budget(study, phi_aug, Qa, Qt, meas, outs, grun, span)
        tm["budget_s"] = time.perf_counter() - t3
    finish(res, tm)
    return res
