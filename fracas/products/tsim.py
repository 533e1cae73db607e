"""The product of one TSIM run (FRACAS TSIM: Monte Carlo with guidance in the loop):
:class:`TsimProduct` and its :class:`TsimManeuver` rows.  Numpy-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["TsimManeuver", "TsimProduct"]


@dataclass
class TsimManeuver:
    """One TSIM maneuver as flown, with TEAM's predictions for it.

    type: "impulsive" | "primary" | "vernier"; law: "linear" | "nonlinear"; time_s (s);
    control_labels / control_units (M,) (impulsive: dv_x, dv_y, dv_z km/s); target_names /
    target_units / target_time_s: its target set; team_correction_cov (M, M): TEAM's
    covariance of the commanded correction (P_ΔV or P_U); team_dv_mean_km_s, team_dv_99_km_s:
    TEAM's exact mean and 99 % |ΔV| (the Hoffman-Young stand-in, digest (G-9); low thrust:
    of the arc's ΔV change, Gaussian); team_target_cov_after (m, m): TEAM's target
    dispersion after this event at its target time, with the process noise from the cutoff
    to the target time (fracas.team.guidance_events); failures: missions it ended (hopeless); near: designs
    accepted within near_success_factor × tolerance."""

    name: str
    type: str
    law: str
    time_s: float
    control_labels: list[str]
    control_units: list[str]
    target_names: list[str]
    target_units: list[str]
    target_time_s: float
    team_correction_cov: np.ndarray
    team_dv_mean_km_s: float
    team_dv_99_km_s: float
    team_target_cov_after: np.ndarray
    failures: int = 0
    near: int = 0


@dataclass
class TsimProduct:
    """The result of one TSIM run (Monte Carlo with guidance in the loop), self-contained.

    table: the per-mission table, every array with a leading mission axis in mission-index
    order (:func:`fracas.tsim.engine.block_fields`: mission, status, failed_maneuver,
    iterations (J), initial_deviation (n), state_deviation (J, 7), knowledge_error (J, n),
    correction (J, M_max), execution_error (J, M_max), dv_km_s (J), dv_total_km_s,
    target_error (m), maneuver_status (J), linear_design_miss / design_miss (J, m), final_mass_kg).  labels (n): the
    augmented state (r, v, m, then parameters); n_state.  final_target_names / units /
    final_target_time_s and team_target_cov (m, m): TEAM's predicted final target
    dispersion (the last maneuver's "after").  statistics: name -> (count, mean, covariance)
    over the successful missions, merged with any a-priori statistics (STAT-1):
    "target_error", "dv_km_s[<maneuver>]", "correction[<maneuver>]", "dv_total_km_s",
    "final_mass_kg"; percentiles: name -> {q: value} from this run's missions; consistency:
    one row per compared output (see :mod:`fracas.tsim.summary`); counts: missions,
    ok, near, hopeless, failed (integration), a_priori (missions merged from earlier runs);
    settings: seed, first_mission, missions, scale, sampling, grid step, block, workers;
    provenance: deck text and path, versions."""

    title: str
    source: str
    epoch_et_s: float
    labels: list[str]
    n_state: int
    maneuvers: list[TsimManeuver]
    final_target_names: list[str]
    final_target_units: list[str]
    final_target_time_s: float
    team_target_cov: np.ndarray
    table: dict[str, np.ndarray]
    statistics: dict[str, tuple[int, np.ndarray, np.ndarray]]
    percentiles: dict[str, dict[float, float]]
    consistency: list[dict[str, Any]]
    counts: dict[str, int]
    settings: dict[str, Any] = field(default_factory=dict)
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
