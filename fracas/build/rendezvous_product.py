"""The rendezvous product: the two-vehicle study, its covariance analysis and single runs ->
:class:`RendezvousProduct` (arrays with labels and units; nothing pointing back at a deck)."""

from __future__ import annotations

from typing import Any

import numpy as np

from fracas.products import RendezvousProduct

__all__ = ["rendezvous_product"]


def _maneuvers(study: Any) -> dict[str, Any]:
    ms = study.maneuvers
    return {
        "maneuver_names": [m.name for m in ms],
        "maneuver_time_s": np.array([m.time_s for m in ms], dtype=np.float64),
        "maneuver_arrival_s": np.array([m.arrival_s for m in ms], dtype=np.float64),
        "maneuver_dv_km_s": np.array([m.dv_km_s for m in ms], dtype=np.float64).reshape(len(ms), 3),
        "maneuver_status": np.array([m.status for m in ms], dtype=np.int64),
    }


def rendezvous_product(
    study: Any, res: Any, runs: dict[str, Any], cfg: Any, timing: dict[str, float], provenance: dict[str, Any]
) -> RendezvousProduct:
    """The run's product.  ``runs``: the single runs' arrays (:func:`fracas.modes.rendezvous.single_run_arrays`)."""
    from fracas.team.two_vehicle import rms_histories

    sr = cfg.single_runs
    return RendezvousProduct(
        title=study.title,
        source=study.source,
        epoch_et_s=study.epoch_et_s,
        centre=study.centre,
        chaser_name=study.chaser_name,
        target_name=study.target_name,
        roles=list(study.roles),
        labels=study.labels,
        units=study.units,
        times_s=study.times_s,
        marks=study.marks,
        x_chaser=study.x_chaser,
        x_target=study.x_target,
        P_true=res.P_true,
        P_assumed=res.P_assumed,
        P_true_minus=res.P_true_minus,
        P_assumed_minus=res.P_assumed_minus,
        maneuver_cov_true=res.maneuver_cov_true,
        maneuver_cov_assumed=res.maneuver_cov_assumed,
        reset_times_s=np.array([study.times_s[r.k] for r in study.resets], dtype=np.float64),
        n_runs=int(sr.runs),
        seed=int(sr.seed),
        run_errors=runs["errors"],
        run_maneuver_errors=runs["maneuver_errors"],
        envelope_1sigma=runs["env1"],
        envelope_3sigma=runs["env3"],
        envelope_1sigma_se=runs["se1"],
        run_rms=runs["rms"],
        reference_sources=list(study.reference_sources),
        team_rms=np.stack(list(rms_histories(res, "true").values()), axis=-1),
        assumed_rms=np.stack(list(rms_histories(res, "assumed").values()), axis=-1),
        envelope_3sigma_se=runs["se3"],
        length_unit=study.length_unit,
        km_per_unit=study.km_per_unit,
        timing=timing,
        run_dynamics=("two_body" if runs["nonlinear"] else "linear") if sr.runs > 0 else "",
        provenance=provenance,
        **_maneuvers(study),
    )
