"""The TEAM engine end to end on the small study (tests/data/team_small.toml, 4 days).

Each test compares the engine with an independent reference: the in-line reference with
the STM-file one, the jitted scan with a plain-numpy re-computation of the filter algebra
from the study's own inputs, the square-root with the covariance form, WLS with Kalman-
Schmidt where they must coincide, PDOT with PHI, a restart from a punched covariance with
the run it was punched from, the results file with the in-memory result, a user gain with
the built-in one.  The study is set up and run once per module (module-scoped fixtures);
variants are built from the deck as a dict and share the base reference where their
schedule is the same (a reference may carry more parameter columns than a study uses).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import tomllib

from fracas.build.team import build_study
from fracas.config.team import parse_team_deck
from fracas.errors import StmFileError
from fracas.modes.stm import build_stm, reference_from_stm
from fracas.modes.team import run_team
from fracas.team.engine import augmented_transitions, exact_inputs, process_noise, run_study
from fracas.team.measure import assemble_measurements
from fracas.team.reference import integrate_reference

DATA = Path(__file__).resolve().parents[1] / "data"
SMALL = DATA / "team_small.toml"
TRAJ = DATA / "team_small_traj.toml"
DAY = 86400.0


# ----------------------------------------------------------------------------- helpers
def dumps(d: dict) -> str:
    """A TEAM deck dict back to TOML (the subset the decks use: tables, arrays of tables,
    inline tables, strings, numbers, booleans, lists)."""
    out: list[str] = []

    def val(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return "{" + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + "}"

    def is_aot(v) -> bool:
        return isinstance(v, list) and bool(v) and isinstance(v[0], dict)

    def table(t: dict, prefix: str) -> None:
        for k, v in t.items():
            if not isinstance(v, dict) and not is_aot(v):
                out.append(f"{k} = {val(v)}")
        for k, v in t.items():
            if isinstance(v, dict):
                out.append(f"[{prefix}{k}]")
                table(v, f"{prefix}{k}.")
            elif is_aot(v):
                for x in v:
                    out.append(f"[[{prefix}{k}]]")
                    table(x, f"{prefix}{k}.")

    table(d, "")
    return "\n".join(out) + "\n"


def small_dict() -> dict:
    return tomllib.loads(SMALL.read_text(encoding="utf-8"))


def study_of(d: dict, source: Path = SMALL):
    """Build the study of a deck dict as if read from ``source`` (relative paths resolve there)."""
    return build_study(parse_team_deck(dumps(d), str(source)))


def write_deck(d: dict, path: Path) -> Path:
    """Write a variant deck elsewhere, its trajectory deck named by absolute path."""
    d = copy.deepcopy(d)
    d["ertraj"]["deck"] = str(TRAJ)
    path.write_text(dumps(d), encoding="utf-8")
    return path


def scaled_diff(A: np.ndarray, B: np.ndarray) -> float:
    """max |A_ij - B_ij| / sqrt(B_ii B_jj) over a covariance history (K, n, n): the error
    relative to each variance (a correlation-sized number; zero-variance rows scale by 1)."""
    d = np.sqrt(np.abs(np.einsum("...ii->...i", B)))
    d = np.where(d > 0, d, 1.0)
    return float(np.max(np.abs(A - B) / d[..., :, None] / d[..., None, :]))


def pos_rss(P: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...ii->...i", P)[..., :3].sum(-1))


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def base():
    """The small study, its in-line reference and its run."""
    study = study_of(small_dict())
    ref = integrate_reference(study)
    return study, ref, run_study(study, ref)


@pytest.fixture(scope="module")
def tmp_mod(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("team_engine")


@pytest.fixture(scope="module")
def stm_path(tmp_mod) -> Path:
    path, _ = build_stm(SMALL, tmp_mod / "team_small_stm.h5")
    return path


# ----------------------------------------------------------------------------- a, b: STM file
def test_base_study_is_what_the_tests_assume(base):
    """Guards the premises of the other tests: roles, tracking used, noise present."""
    study, _, res = base
    assert study.roles == ["solve_for", "solve_for", "dynamic_consider", "measurement_consider", "ignore"]
    assert study.gencov and study.filter_kind == "kalman_schmidt"
    # every scheduled observation has a record (2 x 19 Doppler + 4 range, by hand), used or
    # skipped below 5 deg elevation (19 used)
    assert len(res.meas.records) == 42
    assert sum(r.used for r in res.meas.records) + sum(res.meas.skipped.values()) == 42
    assert sum(r.used for r in res.meas.records) >= 15
    assert np.any(res.Q_assumed != 0) and not res.psd_problems
    # tracking must have shrunk the a-priori 1 m/s velocity sigmas (497 mm/s RSS at 3 d,
    # the thrust uncertainty keeping it there; 1.7 m/s a priori)
    k3 = study.schedule.index_of(3.0 * DAY)
    vel = lambda P: np.sqrt(np.einsum("ii->i", P)[3:6].sum())
    assert vel(res.Pa_plus[k3]) < 0.5 * vel(study.P0_assumed)


def test_stm_file_equals_in_line(base, stm_path):
    """Reference: the in-line run.  The file was integrated once over its 2 h grid and the
    study's times, then chained; the in-line run stops only at the study's times, so the
    two differ by the integrator's truncation (the STM-file engineer measured ~1e-9
    relative on the matrices; here the covariances agree to 5e-11 of each variance).
    Tolerance 1e-8 of each variance: 200x the measured, far below any modelling effect."""
    study, _, res = base
    ref_f = reference_from_stm(study, stm_path)
    assert ref_f.source == str(stm_path)
    res_f = run_study(study, ref_f)
    np.testing.assert_allclose(ref_f.times_s, res.times_s, rtol=0, atol=0)
    assert scaled_diff(res_f.Pa_minus, res.Pa_minus) < 1e-8
    assert scaled_diff(res_f.Pa_plus, res.Pa_plus) < 1e-8
    assert scaled_diff(res_f.Pt_plus, res.Pt_plus) < 1e-8


def test_changed_schedule_through_the_same_file(base, stm_path):
    """A second study tracking Doppler every 8 h (a subset of the 2 h file grid) and range
    from day 1 reads the same file and equals its own in-line run (same tolerance and
    reason as above)."""
    d = small_dict()
    for t in d["tracking"]:
        t["interval_hours"] = 8.0 if t["type"] == "doppler2" else 24.0
    d["tracking"][2]["start_days"] = 1.0
    study = study_of(d)
    assert study.schedule.n != base[0].schedule.n  # really another schedule
    res_f = run_study(study, reference_from_stm(study, stm_path))
    res_i = run_study(study, integrate_reference(study))
    assert scaled_diff(res_f.Pa_plus, res_i.Pa_plus) < 1e-8
    assert scaled_diff(res_f.Pt_plus, res_i.Pt_plus) < 1e-8
    # and it is another answer than the base study's (fewer measurements, larger sigma)
    assert pos_rss(res_f.Pa_plus[-1]) > 1.05 * pos_rss(base[2].Pa_plus[-1])


def test_refusals_parameter_missing(stm_path):
    d = small_dict()
    d["parameter"].append({"label": "mu[earth]", "sigma": 1.0, "role": "consider"})
    with pytest.raises(
        StmFileError,
        match=r"mu\[earth\] not on the STM file; it has thrust_scale, "
        r"bias_in_rad, mu\[sun\], cr",
    ) as e:
        reference_from_stm(study_of(d), stm_path)
    assert str(stm_path) in str(e.value) and "\n" not in str(e.value)


def test_refusals_time_missing(stm_path):
    """Doppler every 3 h: 3 h is not on the 2 h file grid."""
    d = small_dict()
    d["tracking"][0]["interval_hours"] = 3.0
    with pytest.raises(
        StmFileError,
        match=r"requested time 10800\.000000 s .* is not on the STM file.*"
        r"regenerate it",
    ) as e:
        reference_from_stm(study_of(d), stm_path)
    assert "\n" not in str(e.value)


def test_refusals_other_trajectory(stm_path, tmp_path):
    """The same study on a trajectory deck with one value changed (C_R 1.3 -> 1.31)."""
    traj = tmp_path / "traj_cr.toml"
    traj.write_text(TRAJ.read_text(encoding="utf-8").replace("cr = 1.3\n", "cr = 1.31\n"), encoding="utf-8")
    assert traj.read_text() != TRAJ.read_text()
    d = small_dict()
    d["ertraj"]["deck"] = str(traj)
    with pytest.raises(StmFileError, match=r"built from another trajectory.*regenerate the STM file") as e:
        reference_from_stm(study_of(d, tmp_path / "study.toml"), stm_path)
    assert str(traj) in str(e.value) and "\n" not in str(e.value)


# ----------------------------------------------------------------------------- d: numpy re-computation
def event_inputs(study, ref, meas):
    """The engine's event inputs in full size: (Φ assumed, Φ true, Qa, Qt, P0a, P0t, H, n)
    over the filter's states: the study's n, or n + 3 with the exact Gauss-Markov model's
    noise states (fracas.team.gm_exact; Q then covers them), DYNO's Q̃ on the x block
    otherwise."""
    nx, n = study.nx, study.layout.n
    if study.noise_model == "exact" and study.has_noise:
        got = exact_inputs(study, ref)
        aug = got["augmented"]
        phit = aug["phi_true"] if aug["phi_true"] is not None else got["phi"]
        H = np.concatenate([meas.H, np.zeros(meas.H.shape[:2] + (3,))], axis=2)
        return got["phi"], phit, got["Qa"], got["Qt"], aug["P0_assumed"], aug["P0_true"], H, n + 3
    phi = augmented_transitions(study, ref)
    Qa, Qt = process_noise(study, ref)
    full = np.zeros((2, len(phi), n, n))
    full[0, :, :nx, :nx], full[1, :, :nx, :nx] = Qa, Qt
    return phi, phi, full[0], full[1], study.P0_assumed, study.P0_true, meas.H, n


def test_first_events_against_numpy(base):
    """Reference: the filter algebra in plain numpy, from the study's own event inputs
    (Φ_aug with the exact Gauss-Markov blocks, its noise Q, H and R): P⁻ = Φ P Φᵀ + Q,
    K = P⁻Hᵀ J⁻¹ on the estimated rows (state, solve-for) and zero on consider/ignore rows
    (the noise states among them), Joseph update; the true covariance with the same
    (assumed) gain, true Φ, Q and R.  Only rounding separates the two (the engine
    symmetrizes, uses a Cholesky solve): 1e-10 of each variance."""
    study, ref, res = base
    L = study.layout
    meas = assemble_measurements(study, ref)
    phi, phit, Qa, Qt, Pa, Pt, Hs, n = event_inputs(study, ref, meas)
    ne = L.n_est
    Pa, Pt = Pa.copy(), Pt.copy()
    n_check = 7
    for k in range(n_check):
        Pam = phi[k] @ Pa @ phi[k].T + Qa[k]
        Ptm = phit[k] @ Pt @ phit[k].T + Qt[k]
        H, Ra, Rt = Hs[k], meas.R_assumed[k], meas.R_true[k]
        J = H @ Pam @ H.T + Ra
        K = np.zeros((n, H.shape[0]))
        K[:ne] = np.linalg.solve(J, H @ Pam[:, :ne]).T
        IKH = np.eye(n) - K @ H
        Pa = IKH @ Pam @ IKH.T + K @ Ra @ K.T
        Pt = IKH @ Ptm @ IKH.T + K @ Rt @ K.T
        assert scaled_diff(res.Pa_minus[k], Pam) < 1e-10, k
        assert scaled_diff(res.Pa_plus[k], Pa) < 1e-10, k
        assert scaled_diff(res.Pt_minus[k], Ptm) < 1e-10, k
        assert scaled_diff(res.Pt_plus[k], Pt) < 1e-10, k
        # Schmidt: the consider/ignore block is not updated by a measurement
        c = slice(ne, n)
        np.testing.assert_allclose(res.Pa_plus[k][c, c], res.Pa_minus[k][c, c], rtol=1e-12, atol=0)
    # the events checked did something: measurements, process noise, a real update
    assert sum(bool(np.any(meas.H[k])) for k in range(n_check)) >= 3
    assert all(np.any(Qa[k]) for k in range(1, n_check)) and not np.any(Qa[0])
    assert np.trace(res.Pa_plus[n_check - 1][3:6, 3:6]) < 0.6 * np.trace(study.P0_assumed[3:6, 3:6])


# ----------------------------------------------------------------------------- e: Monte Carlo
def test_monte_carlo_closed_loop(base):
    """Reference: the sample covariance of a simulated, linearized closed loop.  4000 runs
    draw the initial errors and parameter values from the TRUE a priori (C_R included,
    which the filter ignores), the process noise from the true Q̃ and the measurement noise
    from the true R (Doppler 2 mm/s), propagate them with the study's Φ_aug, and run the
    actual Schmidt estimator with the study's gains (from the engine's assumed P⁻ and the
    assumed R).  The estimation error's sample variances must match the engine's true
    P⁺: the normalized sample variance has a standard deviation sqrt(2/N) = 0.022; tolerance
    5 of those (0.11) on every variance at three times.  Seeded: the same draw every run."""
    study, ref, res = base
    L = study.layout
    ne = L.n_est
    meas = assemble_measurements(study, ref)
    _, phi, _, Qt, _, P0t, Hs, n = event_inputs(study, ref, meas)
    rng = np.random.default_rng(20281001)
    N = 4000

    def draw(C: np.ndarray, size: int) -> np.ndarray:
        w, V = np.linalg.eigh(0.5 * (C + C.T))
        return rng.standard_normal((size, len(w))) @ (V * np.sqrt(np.clip(w, 0.0, None))).T

    e = draw(P0t, N)  # true errors (state), true parameter values and thrust errors
    xh = np.zeros((N, n))  # the estimate (consider/ignore rows stay zero)
    checked = {5: None, 14: None, study.schedule.n - 1: None}
    for k in range(study.schedule.n):
        e = e @ phi[k].T + draw(Qt[k], N)
        xh = xh @ phi[k].T
        H, Ra, Rt = Hs[k], meas.R_assumed[k], meas.R_true[k]
        Pm = res.Pa_minus[k]
        K = np.zeros((n, H.shape[0]))
        K[:ne] = np.linalg.solve(H @ Pm @ H.T + Ra, H @ Pm[:, :ne]).T
        z = e @ H.T + draw(Rt, N)
        xh = xh + (z - xh @ H.T) @ K.T
        if k in checked:
            err = e - xh
            checked[k] = (
                np.mean(err**2, axis=0),
                np.einsum("ii->i", res.Pt_plus[k]),
                np.einsum("ii->i", res.Pa_plus[k]),
            )
    for k, (mc, true, _assumed) in checked.items():
        live = true > 0
        np.testing.assert_allclose(mc[live] / true[live], 1.0, rtol=0, atol=0.11, err_msg=f"event {k}")
    # not vacuous: the closed loop tells the true from the assumed covariance (2 mm/s Doppler
    # and the ignored C_R make the real position variance 1.65x the assumed at the end;
    # measured sample/true variance ratios 0.96-1.03)
    mc, true, assumed = checked[study.schedule.n - 1]
    assert mc[:3].sum() / assumed[:3].sum() > 1.3


# ----------------------------------------------------------------------------- f: filter forms
def test_square_root_equals_covariance_form(base):
    """Reference: the covariance-form run.  Both are exact algebra; the square-root form
    (triangular factors, sqrt Joseph) differs by rounding amplified by the conditioning
    (measured 1.5e-11 of each variance); tolerance 1e-9."""
    _, ref, res = base
    d = small_dict()
    d["filter"]["square_root"] = True
    del d["event"][1]  # no prediction: not part of this comparison (saves its integration)
    res_s = run_study(study_of(d), ref)
    assert res_s.study.square_root
    assert scaled_diff(res_s.Pa_plus, res.Pa_plus) < 1e-9
    assert scaled_diff(res_s.Pt_plus, res.Pt_plus) < 1e-9


def test_wls_equals_ks_without_noise_and_consider(base):
    """Sequential WLS computes its gain from the non-consider covariance propagated without
    process noise; with no process noise and no consider parameters that is the Kalman-
    Schmidt covariance, so both gains and both histories coincide (rounding only,
    measured 1e-11; tolerance 1e-9).  On the base study (thrust noise, two consider
    parameters) they must differ materially (checked too, so the equality is not vacuous)."""
    _, ref, res = base
    d = small_dict()
    d["filter"]["type"] = "wls"
    del d["event"][1]
    res_w = run_study(study_of(d), ref)
    assert not res_w.psd_problems and np.all(np.isfinite(res_w.Pa_plus))
    assert scaled_diff(res_w.Pa_plus, res.Pa_plus) > 1e-2
    d = small_dict()
    del d["thrust_noise"], d["event"][1]
    d["parameter"] = [p for p in d["parameter"] if p["role"] == "solve_for"]
    ks = run_study(study_of(d), ref)
    d["filter"]["type"] = "wls"
    wls = run_study(study_of(d), ref)
    assert ks.study.layout.nu == ks.study.layout.nv == 0 and not ks.study.has_noise
    assert scaled_diff(wls.Pa_plus, ks.Pa_plus) < 1e-9
    assert scaled_diff(wls.Pt_plus, ks.Pt_plus) < 1e-9


def test_user_gain_equals_kalman_schmidt(base):
    """tests/team/user_gains.py writes the KS gain with jax.numpy (a plain solve instead of
    Cholesky): rounding only (measured 1.2e-11); tolerance 1e-9."""
    _, ref, res = base
    d = small_dict()
    d["filter"]["type"] = "user"
    d["filter"]["user_gain"] = "tests.team.user_gains:ks_gain"
    del d["event"][1]
    res_u = run_study(study_of(d), ref)
    assert res_u.study.user_gain is not None
    assert scaled_diff(res_u.Pa_plus, res.Pa_plus) < 1e-9
    assert scaled_diff(res_u.Pt_plus, res.Pt_plus) < 1e-9


# ----------------------------------------------------------------------------- g: PHI vs PDOT
def _pdot_pair(ref, d: dict, step_hours: float | None = None):
    d = copy.deepcopy(d)
    phi = run_study(study_of(d), ref)
    d["errcon"] = {"propagation": "pdot"}
    if step_hours is not None:
        d["ertraj"]["pdot_step_hours"] = step_hours
    return phi, run_study(study_of(d), ref)


def test_pdot_and_phi_position_sigmas(base):
    """Different noise models: PHI adds DYNO's Q̃ per interval, PDOT carries the Gauss-Markov
    errors as states (a stationary start).  Measured PDOT/PHI position RSS: 0.949 final,
    0.63-1.00 over the history on this study (0.985 and 0.70-1.00 on a variant without
    thrust-bias parameters).  Tolerances: 0.8-1.25 final, 0.5-2 throughout (same order,
    another model)."""
    _, ref, _ = base
    d = small_dict()
    del d["event"][1]
    d["errcon"] = {"process_noise": "interval"}  # FRACAS's per-interval DYNO (the numbers above)
    phi, pdot = _pdot_pair(ref, d)
    n = phi.study.layout.n
    assert pdot.Pa_plus.shape[-1] == n + 3 and pdot.labels[n:] == [
        "eta_proportionality",
        "eta_in_plane_rad",
        "eta_out_of_plane_rad",
    ]
    ratio = pos_rss(pdot.Pa_plus[:, :n, :n]) / pos_rss(phi.Pa_plus)
    print(f"PDOT/PHI position RSS: final {ratio[-1]:.4f}, range {ratio.min():.3f}-{ratio.max():.3f}")
    assert 0.8 < ratio[-1] < 1.25
    assert 0.5 < ratio.min() and ratio.max() < 2.0


def test_pdot_equals_exact_phi_with_noise(base):
    """The exact PHI model (default) and PDOT carry the same noise states with the same
    equations (issue 24); on the small study (measurements, gencov, thrust noise, thrust
    bias parameters) they differ by PDOT's RK4 step error only.  Measured in the test's
    printout; tolerance 1e-5 of each variance over the whole history and the noise-state
    block included (DYNO's models differ from both by up to 0.5x in sigma here)."""
    study, ref, res = base
    assert study.noise_model == "exact" and res.noise_states
    d = small_dict()
    del d["event"][1]
    d["errcon"] = {"propagation": "pdot"}
    pdot = run_study(study_of(d), ref)
    e_a = scaled_diff(pdot.Pa_plus, res.Pa_plus)
    e_t = scaled_diff(pdot.Pt_plus, res.Pt_plus)
    print(f"PDOT vs exact PHI with thrust noise: {e_a:.2e} assumed, {e_t:.2e} true")
    assert e_a < 1e-5 and e_t < 1e-5


def _zero_noise_no_thrust_bias() -> dict:
    d = small_dict()
    del d["thrust_noise"], d["event"][1]
    d["parameter"] = [p for p in d["parameter"] if p["label"] not in ("thrust_scale", "bias_in_rad")]
    return d


def test_pdot_equals_phi_without_noise(base):
    """With zero thrust noise both modes propagate the same covariance exactly: PHI with the
    integrator's Φ and Θ, PDOT by RK4 on Ṗ = FP + PFᵀ.  Their difference is RK4's step
    error: measured 6.7e-9 of each variance at the 2.4 h step and 4.2e-10 at 1.2 h
    (ratio 16 = 2⁴, RK4's order).  Tolerance 5e-8 at 2.4 h; the error must fall by at
    least 8x when the step halves (order >= 3)."""
    _, ref, _ = base
    d = _zero_noise_no_thrust_bias()
    phi, pdot = _pdot_pair(ref, d)
    n = phi.study.layout.n
    e1 = scaled_diff(pdot.Pa_plus[:, :n, :n], phi.Pa_plus)
    assert e1 < 5e-8
    assert scaled_diff(pdot.Pt_plus[:, :n, :n], phi.Pt_plus) < 5e-8
    _, pdot2 = _pdot_pair(ref, d, step_hours=1.2)
    e2 = scaled_diff(pdot2.Pa_plus[:, :n, :n], phi.Pa_plus)
    print(f"PDOT vs PHI without noise: {e1:.2e} (2.4 h step), {e2:.2e} (1.2 h)")
    assert e2 < e1 / 8


def test_pdot_equals_phi_without_noise_with_thrust_bias(base):
    """As above on the small study itself (thrust_scale and bias_in_rad solved for), same
    reference.  With the labels de-duplicated (checked by patching jacobians_at) the
    difference is RK4's again: 7.1e-7 of each variance at 2.4 h, 4.2e-8 at 1.2 h (the
    thrust_scale variance, the most sensitive); tolerance 2e-6.  Before the fix of the
    duplicated labels (B columns of thrust_scale, bias_in_rad zero): 4e3."""
    _, ref, _ = base
    d = small_dict()
    del d["thrust_noise"], d["event"][1]
    phi, pdot = _pdot_pair(ref, d)
    n = phi.study.layout.n
    assert scaled_diff(pdot.Pa_plus[:, :n, :n], phi.Pa_plus) < 2e-6


# ----------------------------------------------------------------------------- h, i: punch, results
@pytest.fixture(scope="module")
def punched(tmp_mod, stm_path):
    """Run the small study with a punch at 1.25 d (between two Doppler passes), then a
    second deck starting from the punched covariance; both through the pipeline with the
    STM file."""
    d = small_dict()
    d["punch"] = {"times_days": [1.25], "file": str(tmp_mod / "punch.h5")}
    first = write_deck(d, tmp_mod / "first.toml")
    res1, out1, _ = run_team(first, stm=stm_path, output=tmp_mod / "first_results.h5")
    d2 = small_dict()
    d2["a_priori"] = {"from_punch": str(tmp_mod / "punch.h5")}
    second = write_deck(d2, tmp_mod / "second.toml")
    res2, _, _ = run_team(second, stm=stm_path, output=tmp_mod / "second_results.h5")
    return res1, out1, res2


def test_restart_from_punch_reproduces_the_run(punched):
    """Reference: the first run after the punch time.  The restart maps with the same
    chained file matrices and the same events from 1.25 d on: rounding only; 1e-10."""
    res1, _, res2 = punched
    t1, t2 = res1.times_s, res2.times_s
    assert t2[0] == 1.25 * DAY and "punch" in res1.event_types[np.searchsorted(t1, 1.25 * DAY)].split("+")
    k0 = int(np.searchsorted(t1, t2[0]))
    np.testing.assert_array_equal(t1[k0:], t2)
    assert list(res2.event_types[1:]) == res1.event_types[k0 + 1 :]
    assert scaled_diff(res2.assumed.P_plus, res1.assumed.P_plus[k0:]) < 1e-10
    assert scaled_diff(res2.true.P_plus, res1.true.P_plus[k0:]) < 1e-10


def test_restart_at_a_measurement_time(tmp_path, stm_path):
    """Punch at 2.0 d, where Goldstone and Madrid Doppler and Goldstone range are taken
    (the punch event comes after the measurement there): the restart's covariance at 2.0 d
    must be the punched one (rounding only: 1e-10)."""
    d = small_dict()
    del d["event"][1]
    d["punch"] = {"times_days": [2.0], "file": str(tmp_path / "punch2.h5")}
    res1, _, _ = run_team(write_deck(d, tmp_path / "a.toml"), stm=stm_path, output=tmp_path / "a.h5")
    d2 = small_dict()
    del d2["event"][1]
    d2["a_priori"] = {"from_punch": str(tmp_path / "punch2.h5")}
    res2, _, _ = run_team(write_deck(d2, tmp_path / "b.toml"), stm=stm_path, output=tmp_path / "b.h5")
    k0 = int(np.searchsorted(res1.times_s, 2.0 * DAY))
    assert res1.event_types[k0].split("+") == ["measurement", "punch"]
    assert not np.any(res2.measurements.index == 0)  # was [0, 1, 2]: measured again
    assert scaled_diff(res2.assumed.P_plus[0], res1.assumed.P_plus[k0]) < 1e-10  # was off by 1.4e-5


def test_restart_from_punch_of_another_trajectory(punched, tmp_mod):
    """A punch from team_small_traj.toml, a restart on the same deck with power_kw 10 -> 10.5:
    refused with a one-line error naming the trajectory (as the STM file's check does)."""
    from fracas.errors import DeckError
    from fracas.modes.stm import load_team

    traj = tmp_mod / "traj_power.toml"
    traj.write_text(TRAJ.read_text(encoding="utf-8").replace("power_kw = 10.0", "power_kw = 10.5"), encoding="utf-8")
    d = small_dict()
    d["a_priori"] = {"from_punch": str(tmp_mod / "punch.h5")}
    d["ertraj"]["deck"] = str(traj)
    deck = tmp_mod / "restart_other.toml"
    deck.write_text(dumps(d), encoding="utf-8")
    with pytest.raises((DeckError, StmFileError), match="trajectory"):
        load_team(deck)


def test_results_file_reads_back(punched):
    """The results file holds the in-memory history exactly (float64 written and read)."""
    from fracas.io.team_results import read_team_results

    res1, out1, _ = punched
    r = read_team_results(out1)
    st = study_of(small_dict())  # the same study, built from the deck
    from fracas.team.result import NOISE_STATE_LABELS, NOISE_STATE_UNITS

    # the exact Gauss-Markov model's noise states follow the parameters (issue 24)
    assert r["labels"] == res1.labels == st.state_labels + st.labels + NOISE_STATE_LABELS
    assert r["units"][:7] == ["km", "km", "km", "km/s", "km/s", "km/s", "kg"]
    assert r["units"][7:] == st.units + NOISE_STATE_UNITS
    assert r["roles"] == ["state"] * 7 + st.roles + ["noise_state"] * 3
    np.testing.assert_array_equal(r["times_s"], res1.times_s)
    np.testing.assert_array_equal(r["assumed"]["P_plus"], res1.assumed.P_plus)
    np.testing.assert_array_equal(r["assumed"]["P_minus"], res1.assumed.P_minus)
    np.testing.assert_array_equal(r["true"]["P_plus"], res1.true.P_plus)
    assert len(r["measurements"]["index"]) == len(res1.measurements.index)


def _datasets(path: Path) -> dict[str, h5py.Dataset]:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(
            lambda name, obj: out.__setitem__(name, dict(obj.attrs)) if isinstance(obj, h5py.Dataset) else None
        )
    return out


def test_results_file_numeric_datasets_have_units(punched):
    found = _datasets(punched[1])
    numeric = {
        k: a
        for k, a in found.items()
        if not k.endswith(("names", "units", "roles", "event_types", "primary", "type", "stations", "psd_problems"))
    }
    assert len(numeric) > 10
    assert [k for k, a in numeric.items() if "units" not in a] == []


def test_results_file_every_dataset_has_units(punched):
    found = _datasets(punched[1])
    assert [k for k, a in found.items() if "units" not in a] == []


# ----------------------------------------------------------------------------- prediction events
@pytest.mark.slow  # ~37 s of a cold make test (mostly XLA compilation; issue 22)
def test_prediction_equals_the_propagated_covariance(base):
    """PRED against the engine's own time updates: without thrust noise (so DYNO's
    interval-length dependence plays no part) and with no measurements after 3 d, the
    knowledge predicted from 3 d to 5 d must equal the covariance the run itself reaches at
    a propagation event at 5 d.  Two branches: (1) 5 d on the schedule -> the stored
    transitions are composed: the same products in another grouping, rounding only (1e-10);
    (2) 5 d not on the schedule -> fresh integration from the stored 3 d state across the
    3.5 d thrust switch: differs from the schedule's chained steps by integration truncation
    only, measured ~1e-9 for other output breaks (STM-file tests), so 1e-7."""
    _, ref, _ = base
    d = small_dict()
    del d["thrust_noise"]
    d["filter"]["stop_days"] = 6.0  # the run must reach 5 d for the comparison
    off = run_study(*_study_ref(d))  # 5 d not a schedule time: integrated branch
    d["event"].append({"type": "propagation", "times_days": [5.0]})
    st, rf = _study_ref(d)
    on = run_study(st, rf)  # 5 d on the schedule: composed branch
    k5 = int(np.argmin(np.abs(on.times_s - 5.0 * 86400.0)))
    assert abs(on.times_s[k5] - 5.0 * 86400.0) < 1e-6
    for res, tol in ((on, 1e-10), (off, 1e-7)):
        ((k, lst),) = res.predictions.items()
        ((t_to, Pa, Pt),) = lst
        assert t_to == 5.0 * 86400.0
        print(f"prediction vs run ({tol:g} branch): {scaled_diff(Pa, on.Pa_plus[k5]):.2e}")
        assert scaled_diff(Pa, on.Pa_plus[k5]) < tol
        assert scaled_diff(Pt, on.Pt_plus[k5]) < tol


def _study_ref(d):
    st = study_of(d)
    return st, integrate_reference(st)


def test_psd_problems_names_the_events(base):
    """Loss of definiteness is reported with its schedule index and event: a history with one
    indefinite covariance (a correlation of 1.01, caught by the scale-free test) and one
    negative variance is flagged exactly there, the healthy events are not."""
    from fracas.team.engine import psd_problems

    study, _, res = base
    from fracas.filters.covariance import psd_check

    # the healthy history takes the Cholesky fast path; psd_check agrees event by event
    assert psd_problems(study, res.Pa_plus, "assumed") == []
    assert all(bool(psd_check(p)[1]) for p in res.Pa_plus)
    P = res.Pa_plus.copy()
    i, j = 0, 3
    P[2, i, j] = P[2, j, i] = 1.01 * np.sqrt(P[2, i, i] * P[2, j, j])
    P[5, 1, 1] = -1e-3 * P[5, 1, 1]
    bad = psd_problems(study, P, "assumed")
    assert [b[0] for b in bad] == [2, 5] and all(b[2] == "assumed" for b in bad)
    assert bad[0][1] == study.schedule.primary_type(2)


def test_run_builds_its_stm_file_when_asked(base, tmp_mod):
    """errcon.build_stm = true: run_team writes the STM file first and then reads the study
    from it (the reference source names the file); the result equals the in-line run to the
    file-vs-in-line tolerance of test (a) (1e-8)."""
    _, _, res0 = base
    d = small_dict()
    stm = tmp_mod / "built_by_run.h5"
    d["errcon"] = {"build_stm": True, "stm_file": str(stm)}
    deck = write_deck(d, tmp_mod / "build_and_run.toml")
    res, _, source = run_team(deck, output=tmp_mod / "build_and_run.h5")
    assert stm.exists() and source == str(stm)
    assert scaled_diff(res.assumed.P_plus, res0.Pa_plus) < 1e-8
