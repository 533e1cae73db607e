"""What a TSIM run flies, in canonical units (FRACAS DATAS's output; digest C.3).

:func:`fracas.build.tsim.build_plan` makes a :class:`TsimPlan` from a TSIM deck and the TEAM
run of the deck it stands on; the engine (:mod:`fracas.tsim.engine`) reads nothing else.
Arrays are numpy float64; km, km/s, kg, s, rad.  Nothing here refers back to a deck.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fracas.dynamics.model import ForceModel, Params

__all__ = ["ManeuverPlan", "TargetPlan", "TsimPlan"]

# Mission status (one per mission, the per-mission table's ``status``)
STATUS_OK = 0
STATUS_NEAR = 1  # a nonlinear design accepted within near_success_factor × tolerance
STATUS_HOPELESS = 2  # a nonlinear design that did not converge: the mission ends there
STATUS_INTEGRATION = 3  # the core stopped early (stop condition, step limit, non-finite)


@dataclass(frozen=True)
class TargetPlan:
    """A target set at its time: names (TARMAT kinds), t_s, the reference values (m,),
    offset (6,): the target body's state relative to the reference's central body at t_s
    (the targets are functions of the spacecraft's state relative to that body), mu of the
    target body (km³/s²), units, and the tolerances (m,) a nonlinear design must meet."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    t_s: float
    reference: np.ndarray
    offset: np.ndarray
    mu: float
    tolerance: np.ndarray


@dataclass(frozen=True)
class ManeuverPlan:
    """One maneuver ($INMAN): the TEAM guidance event it flies and TEAM's predictions.

    type: "impulsive" | "primary" | "vernier"; time_s: t_G or t_I;
    law: "linear" | "nonlinear"; gamma (M, n): δU = −Γ δX̂ (TEAM's guidance matrix about the
    reference, over the augmented state); knowledge_factor (n, n): L with L Lᵀ = P_k, the
    knowledge covariance sampled at the maneuver; control_labels (M,) (low thrust: the
    arc parameters it changes); k_pinv (M, m): the weighted pseudo-inverse K^{+W} of
    K = ∂T/∂U about the reference (impulsive: Ψ_v), kk (M, M) = K^{+W} K (how much of
    an earlier command on the same arc a vernier replaces); dv_jacobian (M,): the arc ΔV
    change per control (low thrust, km/s per unit); sigma_p, sigma_pointing_rad,
    sigma_res_km_s: execution errors (Gates; low thrust: sigma_p fraction of each control);
    team: TEAM's prediction for this event (correction_cov, dv_mean_km_s, dv_99_km_s,
    target_cov_before, target_cov_after: the target dispersion at the target time, the
    process noise after the cutoff included, fracas.team.guidance_events)."""

    name: str
    type: str
    time_s: float
    law: str
    max_iterations: int
    target: TargetPlan
    gamma: np.ndarray
    knowledge_factor: np.ndarray
    control_labels: tuple[str, ...]
    control_units: tuple[str, ...]
    k_pinv: np.ndarray
    kk: np.ndarray
    dv_jacobian: np.ndarray
    sigma_p: float
    sigma_pointing_rad: float
    sigma_res_km_s: float
    team: dict = field(default_factory=dict)

    @property
    def impulsive(self) -> bool:
        return self.type == "impulsive"

    @property
    def n_controls(self) -> int:
        return int(self.gamma.shape[0])


@dataclass(frozen=True)
class TsimPlan:
    """Everything a TSIM block needs.

    model/params/ephem/epoch_et_s: the nominal model (the real world is drawn about it);
    x0 (7,): the reference initial state at t = 0; labels (n,) the augmented state's
    parameter labels after the nx state components; dyn_labels / dyn_index: the labels the
    trajectory depends on and their augmented indices (their sampled deviations change the
    real world's Params); est_dyn (len(dyn_labels),) bool: those the guidance estimates (its
    nonlinear design flies them at their estimated values); init_factor (n, n): L₀ of the
    injection and parameter dispersions (scaled); noise_sigma (3,), noise_tau_s (3,): the
    true Gauss-Markov thrust errors (proportionality, in-plane rad, out-of-plane rad); grid_s
    (S+1,): the noise hold nodes (every maneuver time and the final time are nodes);
    x_ref (J+1, 7): the reference at each maneuver and at the final target time; maneuvers;
    final: the mission's target set (the last maneuver's) and its TEAM prediction
    final_team (target_cov); seed; near_success_factor; isp_s (impulsive engine, for the
    propellant of the corrections); first_mission, missions; block: missions per block.
    """

    model: ForceModel
    params: Params
    ephem: object
    epoch_et_s: float
    x0: np.ndarray
    nx: int
    labels: tuple[str, ...]
    dyn_labels: tuple[str, ...]
    dyn_index: np.ndarray
    est_dyn: np.ndarray
    init_factor: np.ndarray
    noise_sigma: np.ndarray
    noise_tau_s: np.ndarray
    grid_s: np.ndarray
    x_ref: np.ndarray
    maneuvers: tuple[ManeuverPlan, ...]
    final: TargetPlan
    final_team: dict
    seed: int
    near_success_factor: float
    isp_s: float
    first_mission: int
    missions: int
    block: int = 32
    impulse_propellant: str = "spent"
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.init_factor.shape[0])

    @property
    def control_labels(self) -> tuple[str, ...]:
        """Every arc parameter a low-thrust maneuver changes (union, in first-use order)."""
        out: list[str] = []
        for m in self.maneuvers:
            if not m.impulsive:
                out += [c for c in m.control_labels if c not in out]
        return tuple(out)

    @property
    def n_blocks(self) -> int:
        return -(-self.missions // self.block)
