"""One propagation as a product: :class:`TrajectoryData` with its optional
:class:`SensitivityData` (``fracas.build.trajectory_product.trajectory_data``; the
trajectory file's contents).  Numpy-only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fracas.status import status_text

__all__ = ["SensitivityData", "TrajectoryData"]


@dataclass
class SensitivityData:
    """Labelled sensitivity matrices at the output times (state order x y z vx vy vz mass).

    stm_step (n,7,7) Phi(t_k, t_{k-1}); stm (n,7,7) Phi(t_k, t_0); par_step (n,7,np)
    dx(t_k)/dp with x(t_{k-1}) fixed; par (n,7,np) dx(t_k)/dp from t_0.  Element (i, j) has
    units ``STATE_UNITS[i] / col_units[j]``.
    """

    stm: np.ndarray
    stm_step: np.ndarray
    par: np.ndarray
    par_step: np.ndarray
    param_labels: tuple[str, ...] = ()
    param_units: tuple[str, ...] = ()


@dataclass
class TrajectoryData:
    """One propagation as stored in a trajectory file (numpy; canonical units; ICRF).

    t_s (n,) s from the epoch (NaN after an early stop); r_km (n,3), v_km_s (n,3),
    mass_kg (n,) relative to ``primary[k]`` (a body name, "" where undefined); status
    0 final time / 1 stop condition / 2 max steps / 3 non-finite (:class:`fracas.status.RunStatus`).
    """

    epoch_et_s: float
    t_s: np.ndarray
    r_km: np.ndarray
    v_km_s: np.ndarray
    mass_kg: np.ndarray
    primary: tuple[str, ...]
    bodies: tuple[str, ...]
    t_final_s: float
    r_final_km: np.ndarray
    v_final_km_s: np.ndarray
    mass_final_kg: float
    primary_final: str
    status: int
    n_steps: int
    n_rect: int
    centre: str = ""
    title: str = ""
    epoch_tdb: str = ""
    n_reject: int = 0  # steps rejected by the error control (tolerance step control)
    integrator: str = ""  # e.g. "dprkn12, cowell, tolerance 1e-12" (fracas.integrate.highorder)
    sensitivities: SensitivityData | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def status_text(self) -> str:
        return status_text(self.status)

    def summary_dict(self) -> dict[str, Any]:
        """Plain-JSON summary of the end of the propagation."""
        return {
            "title": self.title,
            "epoch_et_s": float(self.epoch_et_s),
            "t_final_s": float(self.t_final_s),
            "r_km": [float(x) for x in self.r_final_km],
            "v_km_s": [float(x) for x in self.v_final_km_s],
            "mass_kg": float(self.mass_final_kg),
            "primary": self.primary_final,
            "status": int(self.status),
            "status_text": self.status_text,
            "n_steps": int(self.n_steps),
            "n_rect": int(self.n_rect),
        }
