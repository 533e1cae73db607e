"""TEAM guidance events through the engine (GUIDM, XGUID, TARMAT) and the error budget.

References, none produced by the code under test:
- Ψ of an impulsive event against central finite differences of re-propagated
  trajectories (fracas.integrate.propagate.propagate from a perturbed state at t_G to t_f);
- the event's ΔV and post-correction covariances against the digest's formulas evaluated
  here directly with numpy on the engine's P_c and P_k (G-3, G-5, G-6, G-7 report form);
- the error budget against independent single-source TEAM runs: the same study with every
  other true error source set to zero (gencov true side), run through the normal engine,
  and against its own total (linearity: contributions sum to the full variance).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fracas.constants import DAY_S
from fracas.integrate.propagate import propagate
from fracas.modes.stm import load_team, stm_product
from fracas.team.engine import run_study
from fracas.team.reference import reference_from_product
from fracas.team.result import team_product

DATA = Path(__file__).resolve().parents[1] / "data"

GUIDANCE = """
[control]
position_sigma_km = [300.0, 300.0, 300.0]
velocity_sigma_km_s = [0.003, 0.003, 0.003]
mass_sigma_kg = 0.5

[[guidance]]
name = "tcm1"
type = "impulsive"
time_days = 3.2
targets = ["x", "y", "z"]

[[guidance]]
name = "lt1"
type = "primary"
time_days = 3.5
arc = 1
controls = ["proportionality", "alpha", "beta"]
targets = ["x", "y", "z"]

[[guidance]]
name = "look"
type = "none"
time_days = 3.9
targets = ["a", "e"]
"""


def _deck(tmp: Path, extra: str = GUIDANCE) -> Path:
    text = (DATA / "team_small.toml").read_text()
    text = text.replace('deck = "team_small_traj.toml"', f'deck = "{(DATA / "team_small_traj.toml").as_posix()}"')
    text = text.split("[punch]")[0] if "[punch]" in text else text
    out = tmp / "guid.toml"
    out.write_text(text + extra)
    return out


@pytest.fixture(scope="module")
def case_ref(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("guid")
    case = load_team(_deck(tmp))
    product = stm_product(case)
    study = case.study
    idx = [list(product.param_labels).index(lab) for lab in study.dynamic_labels]
    sel = dataclasses.replace(  # the study's columns, as read_stm_file(labels=...) gives them
        product,
        par_step=product.par_step[:, :, idx],
        param_labels=[product.param_labels[i] for i in idx],
        param_units=[product.param_units[i] for i in idx],
        param_values=np.asarray(product.param_values)[idx],
        param_steps=np.asarray(product.param_steps)[idx],
    )
    ref = reference_from_product(study, sel, "memory")
    res = run_study(study, ref, product=sel)
    return case, sel, ref, res


def test_guidance_events_ran(case_ref):
    """Smoke: three events in time order, finite covariances, rank 3 for three targets."""
    _, _, _, res = case_ref
    assert [g.name for g in res.guidance] == ["tcm1", "lt1", "look"]
    assert res.guidance[0].rank == 3 and res.guidance[1].rank == 3
    assert np.all(np.isfinite(res.control))
    assert res.budget is not None


def test_psi_against_repropagated_differences(case_ref):
    """Ψ of tcm1 (x, y, z at the trajectory end w.r.t. the state at t_G): central
    differences of re-propagated trajectories.  Steps 1 km and 1e-6 km/s; the differences'
    truncation error is below 1e-7 of each column here, tolerance 1e-6 relative to the
    column's largest entry (the STM file's chained Φ is exact to integration round-off)."""
    case, product, _, res = case_ref
    st = case.study
    g = res.guidance[0]
    pr = st.problem
    i_g = int(np.argmin(np.abs(product.times_s - g.time_s)))
    x_g = np.asarray(product.states[i_g], dtype=np.float64)
    t_out = np.array([g.time_s, g.target_time_s])
    steps = [1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6, 1e-3]
    for j, h in enumerate(steps):
        xp, xm = x_g.copy(), x_g.copy()
        xp[j] += h
        xm[j] -= h
        fp = np.asarray(propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, xp, t_out).x)[-1, :3]
        fm = np.asarray(propagate(pr.model, pr.params, pr.ephem, pr.epoch_et_s, xm, t_out).x)[-1, :3]
        fd = (fp - fm) / (2 * h)
        scale = np.max(np.abs(g.psi[:, j])) + 1e-300
        assert np.max(np.abs(fd - g.psi[:, j])) < 1e-6 * scale, (j, fd, g.psi[:, j])


def test_impulsive_event_against_digest_formulas(case_ref):
    """P_ΔV = Γ P_c Γᵀ with Γ = Ψ_v⁻¹ Ψ_x (report model, three targets, G-3/G-5), the Gates
    average Σ_ex (G-6) and P_T⁺ = Ψ (P_k + B Σ_ex Bᵀ) Ψᵀ on the state block plus the kept
    parameter dispersion (G-7 report form) plus the noise after t_G, evaluated here with numpy from the engine's own
    P_c and P_k at t_G.  Tolerance 1e-9 relative (matrix products in another order)."""
    case, _, _, res = case_ref
    st = case.study
    g = res.guidance[0]
    nx = st.nx
    k = g.index
    assert "measurement" not in st.schedule.events[k]  # so P_k before the event is P_minus
    p_k = res.Pt_minus[k]
    # P_c before the event: the control history just before k, propagated one interval
    pc_prev = res.control[k - 1]
    from tests.team.test_team_engine import event_inputs

    # the engine's full-size inputs: with the exact Gauss-Markov model (issue 24) the noise
    # states are part of the control covariance, their Q and Gamma too
    _, phit, _, Qt, *_ = event_inputs(st, res.ref, res.meas)
    p_c = phit[k] @ pc_prev @ phit[k].T + Qt[k]
    psi = g.psi
    gamma = np.linalg.solve(psi[:, 3:6], psi[:, :nx])
    gamma = np.concatenate([gamma, np.zeros((3, psi.shape[1] - nx))], axis=1)
    p_dv = gamma @ p_c @ gamma.T
    np.testing.assert_allclose(g.correction_cov, p_dv, rtol=1e-9, atol=1e-9 * np.max(np.abs(p_dv)))
    sp, sb, sr = 0.01, 7e-3, 1e-5
    sig = sp**2 * p_dv + sb**2 * (np.trace(p_dv) * np.eye(3) - p_dv) + sr**2 * np.eye(3)
    np.testing.assert_allclose(g.execution_cov, sig, rtol=1e-9, atol=1e-9 * np.max(np.abs(sig)))
    post = p_c.copy()
    post[:nx, :] = p_k[:nx, :]
    post[:, :nx] = p_k[:, :nx]
    post[3:6, 3:6] += sig
    # at the target time: plus the process noise from t_G on (issue 32; its own reference:
    # tests/team/test_target_noise.py)
    want = psi @ post @ psi.T + g.target_noise_cov
    np.testing.assert_allclose(g.target_cov_after, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))
    # the knowledge after the event carries the execution errors (the navigator does not see them)
    jump = res.Pt_plus[k] - res.Pt_minus[k]
    want_jump = np.zeros_like(jump)
    want_jump[3:6, 3:6] = sig
    np.testing.assert_allclose(jump, want_jump, rtol=0, atol=1e-12 * np.max(np.abs(res.Pt_plus[k])))


def _single_source(study, src):
    guid = tuple(
        dataclasses.replace(g, sigma_res_km_s=g.sigma_res_km_s if src == "execution resolution" else 0.0)
        for g in study.guidance
    )
    nx = study.nx
    n = study.layout.n
    P0t = np.zeros((n, n))
    P0c = np.zeros((n, n))
    true_sigma = np.zeros_like(study.true_sigma)
    noise = np.zeros(3)
    if src == "a-priori state":
        P0t[:nx, :nx] = study.P0_true[:nx, :nx]
    elif src == "injection dispersion":
        P0c[:nx, :nx] = study.P0_control[:nx, :nx]
    elif src in study.labels:
        i = nx + study.labels.index(src)
        P0t[i, i] = study.P0_true[i, i]
        P0c[i, i] = study.P0_control[i, i]
    elif src.endswith(" noise") and src != "thrust noise":
        kind = src[: -len(" noise")]
        true_sigma = np.where([t.kind == kind for t in study.tracking], study.true_sigma, 0.0)
    elif src == "thrust noise":
        noise = study.noise_sigma_true
    return dataclasses.replace(
        study,
        gencov=True,
        P0_true=P0t,
        P0_control=P0c,
        true_sigma=true_sigma,
        noise_sigma_true=noise,
        guidance=guid,
        budget=False,
    )


def test_budget_sums_to_total_and_matches_single_source_runs(case_ref):
    """Linearity: Σ_s contribution_s = total to 1e-10 relative (round-off of ~10 sums of
    products of O(1e6) numbers), and each contribution equals an independent TEAM run with
    only that source on the true side (the gains, which come from the assumed covariance,
    are unchanged; the guidance events follow the last measurement so the execution errors
    do not reach the gains), to 1e-8 of the output's total."""
    case, product, ref, res = case_ref
    b = res.budget
    assert b.sum_check < 1e-10
    np.testing.assert_allclose(b.variance.sum(axis=1), b.total, rtol=1e-10)
    from fracas.team.budget import budget_outputs

    for j, src in enumerate(b.sources):
        st = _single_source(case.study, src)
        r1 = run_study(st, ref, product=product)
        _, _, vals = budget_outputs(st, r1.Pt_plus, r1.guidance)
        np.testing.assert_allclose(vals, b.variance[:, j], rtol=0, atol=1e-8 * np.max(np.abs(b.total)), err_msg=src)


def test_results_file_round_trip(case_ref, tmp_path):
    """The guidance, control and budget groups written and read back unchanged."""
    from fracas.io.team_results import read_team_results, write_team_results

    _, _, ref, res = case_ref
    prod = team_product(res, reference_source="memory")
    p = tmp_path / "r.h5"
    write_team_results(p, prod)
    r = read_team_results(p)
    assert [g["name"] for g in r["guidance"]] == ["tcm1", "lt1", "look"]
    np.testing.assert_array_equal(r["guidance"][0]["correction_cov"], res.guidance[0].correction_cov)
    np.testing.assert_array_equal(r["control"]["P_plus"], res.control)
    np.testing.assert_array_equal(r["budget"]["variance"], res.budget.variance)
    assert r["budget"]["sources"] == res.budget.sources
    assert abs(res.guidance[0].time_s - 3.2 * DAY_S) < 1e-6


def test_control_covariance_punched_and_reloaded(case_ref, tmp_path):
    """A punch file carries the control covariance at the punch time; a study reloaded from it
    (a_priori.from_punch, no [control]) starts its control covariance from it, bit for bit."""
    from fracas.build.team import build_case
    from fracas.io.team_results import read_punch, write_punch

    case, _, _, res = case_ref
    prod = team_product(res, reference_source="memory")
    k = res.study.schedule.index_of(3.6 * DAY_S)
    p = tmp_path / "punch.h5"
    write_punch(p, prod, [k])
    punched = read_punch(p)
    n = res.study.layout.n  # the exact model's noise states follow (issue 24), punched beside
    np.testing.assert_array_equal(punched["control"], res.control[k][:n, :n])
    np.testing.assert_array_equal(punched["control_with_noise_states"], res.control[k])
    deck = case.deck.model_copy(update={"control": None})
    study = build_case(deck, punched).study
    np.testing.assert_array_equal(study.P0_control, res.control[k][:n, :n])
    np.testing.assert_array_equal(study.P0_noise_states[2], res.control[k])


@pytest.mark.parametrize("model, sign", [("orthogonal", -1.0), ("tsim", 1.0)])
def test_estimate_models_and_reset_options(case_ref, model, sign):
    """The P̃ models of the digest (G-0) through the engine: P_ΔV = Γ (P_c ± P_k) Γᵀ for
    ``orthogonal`` (−) and ``tsim`` (+), with P_c and P_k the engine's own before the event
    (numpy, 1e-9 relative); and ``guidance_reset = "all"`` sets the control covariance's
    parameter block to the knowledge's too (the default keeps the parameters' dispersion)."""
    case, product, ref, _ = case_ref
    st = dataclasses.replace(case.study, guidance_model=model, budget=False)
    res = run_study(st, ref, product=product)
    g = res.guidance[0]
    k, nx = g.index, st.nx
    from tests.team.test_team_engine import event_inputs

    _, phit, _, Qt, *_ = event_inputs(st, res.ref, res.meas)  # full size: the noise states too
    p_c = phit[k] @ res.control[k - 1] @ phit[k].T + Qt[k]
    p_k = res.Pt_minus[k]
    gamma = g.gamma
    want = gamma @ (p_c + sign * p_k) @ gamma.T
    np.testing.assert_allclose(g.correction_cov, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))

    st_all = dataclasses.replace(case.study, guidance_reset="all", budget=False)
    r_all = run_study(st_all, ref, product=product)
    ka = r_all.guidance[0].index
    np.testing.assert_allclose(r_all.control[ka][nx:, nx:], r_all.Pt_minus[ka][nx:, nx:], rtol=1e-12, atol=0)
    r_def = run_study(dataclasses.replace(case.study, budget=False), ref, product=product)
    assert not np.allclose(r_def.control[ka][nx:, nx:], r_def.Pt_minus[ka][nx:, nx:])


def test_guidance_on_state_and_solve_for(case_ref):
    """``guidance_estimates = "state_and_solve_for"``: Γ acts on the state and the solve-for
    columns only (consider and ignore columns zero; the default law: state only), and Γ is
    the least-norm solution of Ψ_v Γ = Ψ on those columns (three targets: Ψ_v Γ equals Ψ
    there to 1e-9 relative)."""
    case, product, ref, res = case_ref
    lay = case.study.layout
    nx, ns = case.study.nx, lay.ns
    g0 = res.guidance[0]
    assert np.all(g0.gamma[:, nx:] == 0.0)
    st = dataclasses.replace(case.study, guidance_estimates="state_and_solve_for", budget=False)
    g = run_study(st, ref, product=product).guidance[0]
    assert np.any(g.gamma[:, nx : nx + ns] != 0.0) and np.all(g.gamma[:, nx + ns :] == 0.0)
    cols = slice(0, nx + ns)
    lhs = g.psi[:, 3:6] @ g.gamma[:, cols]
    np.testing.assert_allclose(lhs, g.psi[:, cols], rtol=1e-9, atol=1e-9 * np.max(np.abs(g.psi[:, cols])))
