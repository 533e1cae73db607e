"""The product of one TOM run (FRACAS TOM: targeting and final-mass optimization):
:class:`TomProduct`.  Numpy-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["TomProduct"]


@dataclass
class TomProduct:
    """The result of one TOM run (targeting and final-mass optimization), self-contained.

    Controls (M) and targets (N) are stored in deck units (``control_units``,
    ``target_units``: days, deg, km, km/s, 1); ``control_factor`` / ``target_factor`` give
    the canonical unit per deck unit.  u_start / u_final (M,) controls; lower / upper (M,)
    bounds; desired / tolerance / achieved (N,) targets, achieved from the plain-core
    re-propagation of u_final (the verification); final_mass_kg, initial_mass_kg.
    History (K iterations): iteration, submode, performance_kg, error_rms, angle_rad, gamma,
    n_trajectories, controls (K, M), targets (K, N).  stop_reason: why the search stopped;
    converged: the verified verdict (every target within tolerance on re-propagation and,
    when optimizing, the search's optimality test); search_converged: the optimizer's own
    claim (recorded, never trusted alone).  s_matrix (N, M), g_vector (M,) at u_final in
    deck units.  trials: every line-search trial trajectory (GENMIN/FUNCT) as rows (iteration,
    γ, F(γ), final mass kg, error index E, ok).  grid: GRID's tables (or None): ``{"single": (M, 2J) E, "single_gammas":
    (2J,), "pairs": {(a, b): (2J, 2J) E}}``.
    """

    title: str
    source: str
    submode: str
    optimizer: str
    sensitivities: str
    control_names: list[str]
    control_units: list[str]
    control_factor: np.ndarray
    u_start: np.ndarray
    u_final: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    target_names: list[str]
    target_bodies: list[str]
    target_units: list[str]
    target_factor: np.ndarray
    desired: np.ndarray
    tolerance: np.ndarray
    achieved_start: np.ndarray
    achieved: np.ndarray
    initial_mass_kg: float
    start_mass_kg: float
    final_mass_kg: float
    stop_reason: str
    converged: bool
    search_converged: bool
    targets_met: bool
    iteration: np.ndarray
    submodes: list[str]
    performance_kg: np.ndarray
    error_rms: np.ndarray
    angle_rad: np.ndarray
    gamma: np.ndarray
    n_trajectories: np.ndarray
    controls: np.ndarray
    targets: np.ndarray
    s_matrix: np.ndarray | None = None
    g_vector: np.ndarray | None = None
    grid: dict | None = None
    trials: np.ndarray | None = None  # (T, 6): iteration, gamma, cost F(gamma), mass kg, E, ok (1/0)
    reference_deck: str = ""
    timing: dict[str, float] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    # what was maximized: "final_mass" (kg) or a target kind ([tom] performance, its deck unit;
    # minimized when maximize = false); its value at the start and final controls, deck units;
    # performance_kg above then holds it per iteration in canonical units
    performance_name: str = "final_mass"
    performance_unit: str = "kg"
    performance_start: float = float("nan")
    performance_final: float = float("nan")

    @property
    def target_error(self) -> np.ndarray:
        """Achieved − desired (deck units; angles wrapped to ±180 deg)."""
        d = np.asarray(self.achieved, float) - np.asarray(self.desired, float)
        ang = np.array([u == "deg" for u in self.target_units], bool)
        if ang.any():
            d[ang] = -np.remainder(-d[ang] + 180.0, 360.0) + 180.0
        return d
