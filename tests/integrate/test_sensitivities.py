"""STM and parameter matrices by forward-mode AD against central finite differences (FRACAS
PTRAN), STM composition, and Liouville's det(Phi) = 1 for the ballistic flow.

Finite-difference steps: 1e-3 km in position, 1e-6 km/s in velocity, 1e-3 kg in mass and
1e-6 relative in parameters: the central-difference truncation error (h^2/6 x''') is then
~1e-12 relative and the roundoff (eps |x| / h) ~1e-9, so AD and FD must agree to ~1e-7 of
each column's size.  Rectification is switched off in these cases (rect_ratio = 10): a
rectification that moves by one step between the + and - runs would put a jump of
integration-error size into the difference quotient, which is a property of FD, not of
the derivative.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fracas.dynamics.model import ForceModel, default_params
from fracas.integrate.propagate import finite_difference_sensitivities, propagate_with_sensitivities
from tests.integrate.methods import KINDS_NO_ENCKE, integrator

MU = 398600.4418
X0 = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0])


# det Phi - 1 for dprkn12 at tol 1e-12 over 6000 s is the integration error of the STM
# (relative local error <= tol per step, summed over the run): measured 1.1e-12 Cowell,
# 8.3e-13 Encke (7e-14, 8e-14 at tol 1e-13); bound with a 100x margin.
DET_BOUND_HIGH_ORDER = 1e-10


def _col_rel_err(ad, fd):
    scale = np.maximum(np.abs(fd).max(axis=0), 1e-300)
    return np.abs(ad - fd).max(axis=0) / scale


def leo_j2(ratio=10.0, c_nom=0.02, kind="fracas"):
    m = ForceModel(bodies=("earth",), j2=True, integrator=integrator(kind, c_nom=c_nom, rect_ratio=ratio))
    return m, default_params(m, mu=[MU], pole=[[0.0, 0.0, 1.0]])


def _ad_and_variational(kind, *args):
    """propagate_with_sensitivities by AD; for Cowell also by the variational equations,
    which must give the same derivative of the same discrete map (1e-10 relative; ~4e-13
    measured)."""
    tr, s = propagate_with_sensitivities(*args, method="ad")
    if kind == "cowell":
        _, v = propagate_with_sensitivities(*args, method="variational")
        for a, b in ((s.stm[-1], v.stm[-1]), (s.par[-1], v.par[-1])):
            a, b = np.asarray(a), np.asarray(b)
            if a.size:
                assert np.abs(a - b).max() / np.abs(a).max() < 1e-10
    return tr, s


def spiral(kind="fracas"):
    """Near-Earth spiral: J2, two thrust arcs (velocity frame, nuclear power so the thrust does
    not need an ephemeris), mass flow: every thrust parameter has a non-zero column."""
    m = ForceModel(
        bodies=("earth",),
        j2=True,
        thrust=True,
        velocity_dependent=True,
        power="nuclear",
        n_arcs=2,
        integrator=integrator(kind, thrust=True, c_nom=0.02, rect_ratio=10.0),
    )
    p = default_params(
        m,
        mu=[MU],
        pole=[[0.0, 0.0, 1.0]],
        power_kw=5.0,
        power_decay_s=3.0e7,
        efficiency=0.6,
        exhaust_velocity_km_s=25.0,
        arc_t_on=[0.0, 3000.0],
        arc_t_off=[2500.0, 5500.0],
        arc_alpha=[0.1, -0.2],
        arc_beta=[0.05, 0.3],
        arc_throttle=[1.0, 0.8],
    )
    return m, p


# every thrust parameter with a live column on the spiral (overall and per-arc proportionality
# and pointing biases, exhaust velocity, power, efficiency, switch times) and mu
THRUST_LABELS = (
    "thrust_scale",
    "bias_in_rad",
    "bias_out_rad",
    "exhaust_velocity_km_s",
    "power_kw",
    "efficiency",
    "arc_thrust_scale[1]",
    "arc_bias_in_rad[0]",
    "arc_bias_out_rad[1]",
    "arc_t_off[0]",
    "arc_t_on[1]",
    "mu[earth]",
)


def thrust_fd_steps(kind):
    """Central-difference steps for THRUST_LABELS (why, in
    test_thrust_parameters_match_finite_differences): 1e-6 (RKN4) or 1e-4 (DOP853) for the
    dimensionless ones, 1e-5 / 1e-3 km/s and kW, 1 s for switch times, 0.1 km^3/s^2 for mu."""
    fr = kind == "fracas"
    small = 1e-6 if fr else 1e-4
    ve_p = 1e-5 if fr else 1e-3  # km/s and kW: 4e-5 and 2e-4 relative for DOP853
    return [small, small, small, ve_p, ve_p, 1e-6 if fr else 1e-4, small, small, small, 1.0, 1.0, 1e-1]


@pytest.mark.slow  # ~163 s of a cold make test (mostly XLA compilation; issue 22)
@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_stm_and_gravity_parameters_match_finite_differences(kind):
    """LEO with J2 over 6000 s: every STM column and d/dmu, d/dJ2 vs central differences.
    For the fracas and cowell kinds (tests/integrate/methods.py; encke left out for time); for
    Cowell the variational equations give the AD result to 1e-10 (measured 3.5e-15)."""
    m, p = leo_j2(kind=kind)
    t_out = np.array([0.0, 6000.0])
    labels = ("mu[earth]", "j2[earth]")
    _, s = _ad_and_variational(kind, m, p, None, 0.0, X0, t_out, labels)
    stm_fd, par_fd = finite_difference_sensitivities(m, p, None, 0.0, X0, t_out, labels)
    err_stm = _col_rel_err(np.asarray(s.stm[-1])[:, :6], stm_fd[:, :6])
    err_par = _col_rel_err(np.asarray(s.par[-1]), par_fd)
    assert err_stm.max() < 1e-6, err_stm
    assert err_par.max() < 1e-6, err_par


@pytest.mark.slow  # AD through thrust arcs: ~60 s of compilation per kind on a cold cache
@pytest.mark.parametrize("kind", ["fracas", "cowell"])
def test_thrust_parameters_match_finite_differences(kind):
    """Every thrust parameter (overall and per-arc proportionality and pointing biases,
    exhaust velocity, power, efficiency, switch times) and the mass column vs FD, for the
    fracas kind and for cowell (DOP853, AD only: thrust has no variational path).

    For DOP853 the proportionality, pointing and efficiency columns take 1e-4 steps (exhaust
    velocity and power 1e-3 km/s, kW), not 1e-6 (1e-5): at 1e-6
    the perturbation moves the final state by only ~1e-5 km, and the runs' rounding
    (~1e-9 km, different stage arithmetic from RKN4) left 1e-5 .. 5e-5 relative noise in the
    difference whatever the step control (tolerance or c_nom); at 1e-4 the columns agree to
    5e-8 .. 5e-7 (truncation h^2 ~ 1e-8 relative)."""
    m, p = spiral(kind)
    t_out = np.array([0.0, 6000.0])
    labels = THRUST_LABELS
    _, s = propagate_with_sensitivities(m, p, None, 0.0, X0, t_out, labels)
    # switch times: 1 s steps; the FD error of these columns is roundoff-bound (~1e-9 km / h,
    # measured 5e-8 relative at h = 1 s, 1.3e-6 at 0.01 s), the h^2 truncation is ~1e-10
    steps = thrust_fd_steps(kind)
    stm_fd, par_fd = finite_difference_sensitivities(m, p, None, 0.0, X0, t_out, labels, param_steps=steps)
    err_stm = _col_rel_err(np.asarray(s.stm[-1]), stm_fd)
    err_par = _col_rel_err(np.asarray(s.par[-1]), par_fd)
    assert err_stm.max() < 1e-6, err_stm
    assert err_par.max() < 1e-6, dict(zip(labels, err_par))
    assert np.all(np.abs(par_fd).max(axis=0) > 0)  # every column is live


def test_dop853_thrust_variational_equals_ad_and_finite_differences():
    """Issue 23: the first-order variational equations (DOP853, Cowell) through two thrust
    arcs with mass flow, against (a) forward-mode AD through the whole integrator: the same
    derivative of the same discrete map, so 1e-10 of each matrix's size (rounding only);
    (b) central differences with the steps of ``test_thrust_parameters_match_finite_differences``
    (why 1e-4 for DOP853 is said there): 1e-6 of each column's size.  Switch times are not
    variational labels (they move a step boundary; ``variational_supported`` refuses them)."""
    from fracas.integrate import highorder

    m, p = spiral("cowell")
    t_out = np.array([0.0, 6000.0])
    keep = [not lab.startswith("arc_t_") for lab in THRUST_LABELS]
    labels = tuple(lab for lab, k in zip(THRUST_LABELS, keep) if k)
    assert highorder.variational_supported(m, labels)
    assert not highorder.variational_supported(m, labels + ("arc_t_off[0]",))
    _, var = propagate_with_sensitivities(m, p, None, 0.0, X0, t_out, labels, method="variational")
    _, ad = propagate_with_sensitivities(m, p, None, 0.0, X0, t_out, labels, method="ad")
    for a, b in ((ad.stm[-1], var.stm[-1]), (ad.par[-1], var.par[-1])):
        a, b = np.asarray(a), np.asarray(b)
        assert np.abs(a - b).max() / np.abs(a).max() < 1e-10
    steps = [h for h, k in zip(thrust_fd_steps("cowell"), keep) if k]
    stm_fd, par_fd = finite_difference_sensitivities(m, p, None, 0.0, X0, t_out, labels, param_steps=steps)
    assert _col_rel_err(np.asarray(var.stm[-1]), stm_fd).max() < 1e-6
    err_par = _col_rel_err(np.asarray(var.par[-1]), par_fd)
    assert err_par.max() < 1e-6, dict(zip(labels, err_par))
    assert np.all(np.abs(par_fd).max(axis=0) > 0)  # every column is live


@pytest.mark.slow  # ~125 s of a cold make test (mostly XLA compilation; issue 22)
@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
def test_ballistic_stm_is_volume_preserving(kind):
    """Liouville: det Phi(t, t0) = 1 for a Hamiltonian flow (no thrust).  The Nystrom map is
    not symplectic, so det deviates at truncation order: < 1e-8 at c_nom 0.01 (measured
    ~1e-10), and the deviation shrinks with the step (>= 10x for c_nom 0.04 -> 0.02).
    The high-order kinds (dprkn12, tol 1e-12; not symplectic either) deviate by their
    integration error of the STM: < DET_BOUND_HIGH_ORDER (see there); for Cowell the
    variational equations give the AD STM to 1e-10."""
    if kind != "fracas":
        m, p = leo_j2(ratio=0.01, kind=kind)
        _, s = _ad_and_variational(kind, m, p, None, 0.0, X0, np.array([0.0, 6000.0]))
        dev = abs(np.linalg.det(np.asarray(s.stm[-1])[:6, :6]) - 1.0)
        assert dev < DET_BOUND_HIGH_ORDER, dev
        return
    devs = []
    for c in (0.04, 0.02, 0.01):
        m, p = leo_j2(ratio=0.01, c_nom=c)
        _, s = propagate_with_sensitivities(m, p, None, 0.0, X0, np.array([0.0, 6000.0]))
        devs.append(abs(np.linalg.det(np.asarray(s.stm[-1])[:6, :6]) - 1.0))
    assert devs[2] < 1e-8, devs
    assert devs[0] / devs[1] > 10.0, devs


@pytest.mark.slow  # ~34 s of a cold make test (mostly XLA compilation; issue 22)
@pytest.mark.parametrize("kind", KINDS_NO_ENCKE)
@settings(max_examples=8, deadline=None)
@given(frac=st.floats(min_value=0.05, max_value=0.95))
def test_stm_composition(kind, frac):
    """Phi(t2, t0) = Phi(t2, t1) Phi(t1, t0), each factor from a run with an extra output at
    t1 (which breaks the step sequence there): equal to integration accuracy, 1e-6 relative
    at c_nom 0.01; the parameter matrices compose the same way.  For the fracas and cowell kinds
    (Cowell at tol 1e-12 through method 'auto', i.e. the variational equations)."""
    m, p = leo_j2(ratio=0.01, c_nom=0.01, kind=kind)
    t2 = 6000.0
    t1 = frac * t2
    labels = ("j2[earth]",)
    _, a = propagate_with_sensitivities(m, p, None, 0.0, X0, np.array([0.0, t2, t2]), labels)
    _, b = propagate_with_sensitivities(m, p, None, 0.0, X0, np.array([0.0, t1, t2]), labels)
    direct = np.asarray(a.stm[-1])
    composed = np.asarray(b.stm_step[2]) @ np.asarray(b.stm_step[1])
    assert np.abs(direct - composed).max() / np.abs(direct).max() < 1e-6
    par_composed = np.asarray(b.stm_step[2]) @ np.asarray(b.par_step[1]) + np.asarray(b.par_step[2])
    assert np.abs(np.asarray(a.par[-1]) - par_composed).max() / np.abs(par_composed).max() < 1e-6
