"""``propagate.final_state_jacobian`` (TOM's sensitivities along the control directions)
against the full STM and parameter matrix of ``propagate_with_sensitivities`` and against
central differences of the plain core (the references this function did not produce).

Both are derivatives of the same integration (forward-mode AD along M directions versus the
explicit variational equations, here on LEO + J2 with DPRKN12); they differ only in that
the Jacobian here also differentiates the step-size choices, an O(tolerance) effect, so
1e-8 relative holds with a wide margin (measured 1.2e-14).  Central differences (1e-4 in the
scaled directions) carry ~1e-8 truncation/rounding; tolerance 1e-6.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fracas.build.trajectory import build_propagation
from fracas.config.trajectory import load_deck
from fracas.dynamics.parameters import get_values, set_values
from fracas.integrate.propagate import final_state_jacobian, propagate, propagate_with_sensitivities

ROOT = Path(__file__).resolve().parents[2]
LABELS = ("j2[earth]", "mu[earth]")


def _setup():
    pr = build_propagation(load_deck(ROOT / "namelists" / "leo_j2.toml"))
    rng = np.random.default_rng(7)
    dx0 = np.zeros((7, 3))
    dx0[:6] = rng.standard_normal((6, 3)) * np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])[:, None]
    dp = rng.standard_normal((2, 3)) * np.array([1e-5, 1.0])[:, None]
    return pr, dx0, dp, np.array([0.0, 0.25 * 86400.0])


@pytest.mark.slow  # ~80 s of a cold make test (mostly XLA compilation; issue 22)
def test_equals_the_stm_and_parameter_matrix_along_the_directions():
    pr, dx0, dp, t_out = _setup()
    x_end, x_u = final_state_jacobian(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, t_out[-1], LABELS, dx0, dp)
    tr, sens = propagate_with_sensitivities(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, t_out, LABELS)
    ref = np.asarray(sens.stm[-1]) @ dx0 + np.asarray(sens.par[-1]) @ dp
    assert np.allclose(np.asarray(x_end), np.asarray(tr.x[-1]), rtol=0, atol=1e-9)
    scale = np.abs(ref).max(axis=1, keepdims=True) + 1e-300
    assert (np.abs(np.asarray(x_u) - ref) / scale).max() < 1e-8


@pytest.mark.slow  # ~0 s of a cold make test (mostly XLA compilation; issue 22)
def test_matches_central_differences_along_the_directions():
    pr, dx0, dp, t_out = _setup()
    _, x_u = final_state_jacobian(pr.model, pr.params, pr.ephem, pr.epoch_et_s, pr.x0, t_out[-1], LABELS, dx0, dp)
    p0 = np.asarray(get_values(pr.params, LABELS, pr.model))
    h = 1e-4
    for j in range(3):
        ends = []
        for sgn in (1.0, -1.0):
            prm = set_values(pr.params, LABELS, p0 + sgn * h * dp[:, j], pr.model)
            ends.append(
                np.asarray(propagate(pr.model, prm, pr.ephem, pr.epoch_et_s, pr.x0 + sgn * h * dx0[:, j], t_out).x[-1])
            )
        fd = (ends[0] - ends[1]) / (2 * h)
        col = np.asarray(x_u)[:, j]
        assert np.abs(col - fd).max() / np.abs(fd).max() < 1e-6, (j, col, fd)
