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

from fracas.team.measure import assemble_measurements
from fracas.team.pdot import run_pdot
from fracas.team.reference import Reference
from fracas.team.result import TeamResult, finish, psd_problems
from fracas.team.scan import run_filter
from fracas.team.study import Study
from fracas.team.transitions import EPS_T, augmented_transitions, interval_noise, process_noise, theta_columns

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
