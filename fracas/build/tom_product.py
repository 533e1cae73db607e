"""TOM's product: the case, the search's result and the verification run -> :class:`TomProduct`
(deck units: each control and target divided by its factor; the performance in its unit)."""

from __future__ import annotations

from typing import Any

import numpy as np

from fracas.products import TomProduct

__all__ = ["tom_product", "deck_performance"]


def deck_performance(case: Any, value: float) -> float:
    """F in the performance's deck unit, its sign undone (F = -value when minimizing)."""
    sign = -1.0 if (case.performance_name != "final_mass" and not case.deck.tom.maximize) else 1.0
    return sign * float(value) / case.performance_factor


def _history(res: Any, fac_u: np.ndarray, fac_t: np.ndarray) -> dict[str, Any]:
    """The search's iteration records as the product's arrays (deck units)."""
    hist = res.history
    return {
        "iteration": np.array([r.iteration for r in hist], np.int64),
        "submodes": [r.submode for r in hist],
        "performance_kg": np.array([r.performance for r in hist], float),
        "error_rms": np.array([r.error_rms for r in hist], float),
        "angle_rad": np.array([r.angle_rad for r in hist], float),
        "gamma": np.array([r.gamma for r in hist], float),
        "n_trajectories": np.array([r.n_evaluations for r in hist], np.int64),
        "controls": np.array([r.u / fac_u for r in hist], float).reshape(len(hist), len(fac_u)),
        "targets": np.array([r.targets / fac_t for r in hist], float).reshape(len(hist), len(fac_t)),
        "trials": np.array(
            [[r.iteration, t.gamma, t.cost, t.performance, t.error_index, float(t.ok)] for r in hist for t in r.trials],
            float,
        ).reshape(-1, 6),
    }


def tom_product(
    case: Any,
    res: Any,
    start: Any,
    final: Any,
    verdict: tuple[str, bool, bool],
    sensitivities: tuple[Any, Any],
    grid: Any,
    reference_deck: str,
    timing: dict[str, float],
    provenance: dict[str, Any],
) -> TomProduct:
    """The TOM run's product.  ``verdict``: (stop reason, converged, targets met);
    ``sensitivities``: (S, G) at the final controls in deck units, or (None, None)."""
    cfg, tg = case.deck, case.problem.targets
    fac_u, fac_t = case.control_factor, case.target_factor
    ev = final.evaluation
    u_final = np.asarray(res.u, float)
    reason, converged, targets_met = verdict
    return TomProduct(
        title=cfg.title or case.trajectory.title,
        source=cfg.source_path or "",
        submode=cfg.tom.submode,
        optimizer=cfg.tom.optimizer,
        sensitivities=cfg.tom.sensitivities,
        control_names=list(case.control_names),
        control_units=list(case.control_units),
        control_factor=fac_u,
        u_start=case.u0 / fac_u,
        u_final=u_final / fac_u,
        lower=case.lower / fac_u,
        upper=case.upper / fac_u,
        target_names=list(tg.names),
        target_bodies=list(case.target_bodies),
        target_units=list(case.target_units),
        target_factor=fac_t,
        desired=tg.desired / fac_t,
        tolerance=tg.tolerance / fac_t,
        achieved_start=start.evaluation.targets / fac_t,
        achieved=(ev.targets if ev.ok else np.full(tg.n_targets, np.nan)) / fac_t,
        initial_mass_kg=float(case.base.x0[6]),
        start_mass_kg=float(start.x_final[6]),
        final_mass_kg=float(final.x_final[6]) if ev.ok else float("nan"),
        performance_name=case.performance_name,
        performance_unit=case.performance_unit,
        performance_start=deck_performance(case, start.evaluation.performance),
        performance_final=deck_performance(case, ev.performance) if ev.ok else float("nan"),
        stop_reason=reason,
        converged=converged,
        search_converged=bool(res.search_converged),
        targets_met=targets_met,
        s_matrix=sensitivities[0],
        g_vector=sensitivities[1],
        grid=grid,
        reference_deck=reference_deck,
        timing=timing,
        provenance=provenance,
        **_history(res, fac_u, fac_t),
    )
