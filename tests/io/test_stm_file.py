"""The STM file (FRACAS STMGEN / STMRDR): round trip, column selection, chaining over skipped
times against plain products and against a real propagation, the trajectory hash, refusals
and atomic writes.

References: exact equality for the file round trip and column selection (HDF5 stores
float64 bit for bit); a plain Python loop of matrix products for :func:`chain` (1e-13
relative: the same products in another association order, roundoff only); and two real
propagations of a short LEO + J2 deck (see ``test_chain_matches_real_propagation``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fracas.build import build_propagation
from fracas.build.reference import stm_data_from_run
from fracas.config.trajectory import parse_deck, trajectory_hash
from fracas.errors import StmFileError
from fracas.integrate.propagate import (
    Sensitivities,
    Trajectory,
    propagate_with_sensitivities,
)
from fracas.io.hdf5 import provenance
from fracas.io.stm_file import (
    FILE_KIND,
    SCHEMA_VERSION,
    StmData,
    check_trajectory,
    describe,
    read_stm_file,
    write_stm_file,
)
from fracas.products import chain
from tests.io.damage import edited

ROOT = Path(__file__).resolve().parents[2]
DAY = 86400.0
LABELS = ["mu[earth]", "j2[earth]", "thrust_scale", "arc_t_on[0]"]
UNITS = ["km^3/s^2", "1", "1", "s"]


def _data(n: int = 6, n_par: int = 3, seed: int = 0, t0: float = 0.0) -> StmData:
    """Random but well-conditioned step matrices (I + 0.1 N(0,1); I and 0 at t = 0) on a 600 s grid."""
    rng = np.random.default_rng(seed)
    stm_step = np.eye(7) + 0.1 * rng.normal(size=(n, 7, 7))
    par_step = rng.normal(size=(n, 7, n_par))
    if t0 == 0.0:  # Phi(0, 0) = I, Theta(0, 0) = 0 (read_stm_file checks)
        stm_step[0], par_step[0] = np.eye(7), 0.0
    events = ["initial"] + [["measurement", "propagation", "grid"][i % 3] for i in range(n - 2)] + ["final"]
    return StmData(
        times_s=t0 + 600.0 * np.arange(n),
        epoch_et_s=946728000.0,
        event_types=events[:n],
        states=rng.normal(size=(n, 7)) * 1e3,
        primary=["earth"] * n,
        stm_step=stm_step,
        par_step=par_step,
        param_labels=LABELS[:n_par],
        param_units=UNITS[:n_par],
        param_values=rng.normal(size=n_par),
        param_steps=np.full(n_par, np.nan),
        deck_text='title = "t"\n',
        deck_hash="ab" * 32,
        deck_path="namelists/t.toml",
        title="random steps",
        centre="earth",
        provenance=provenance('title = "t"\n', "namelists/t.toml"),
    )


def _assert_same(a: StmData, b: StmData) -> None:
    for name in ("times_s", "states", "stm_step", "par_step", "param_values", "param_steps"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)  # bit-exact, NaN == NaN
    for name in (
        "epoch_et_s",
        "event_types",
        "primary",
        "param_labels",
        "param_units",
        "deck_text",
        "deck_hash",
        "deck_path",
        "title",
        "centre",
        "frame",
        "fracas_version",
        "schema_version",
        "sensitivity_method",
        "provenance",
    ):
        assert getattr(a, name) == getattr(b, name), name


# --------------------------------------------------------------------------- file layout


@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 8), n_par=st.integers(0, 4), seed=st.integers(0, 2**32 - 1))
def test_round_trip_is_identity(tmp_path_factory, n, n_par, seed):
    d = _data(n, n_par, seed)
    path = tmp_path_factory.mktemp("rt") / "s.h5"
    write_stm_file(path, d)
    back = read_stm_file(path)
    assert back.source_path == str(path)
    _assert_same(d, back)


def test_every_dataset_has_units_and_columns_are_chunks(tmp_path):
    path = tmp_path / "s.h5"
    write_stm_file(path, _data(5, 3))
    missing = []
    with h5py.File(path, "r") as f:
        assert f.attrs["file_kind"] == FILE_KIND and int(f.attrs["schema_version"]) == SCHEMA_VERSION
        assert f.attrs["sensitivity_method"] == "ad"
        f.visititems(
            lambda name, obj: (
                missing.append(name) if isinstance(obj, h5py.Dataset) and "units" not in obj.attrs else None
            )
        )
        par = f["stm/par_step"]
        assert par.shape == (3, 5, 7) and par.chunks == (1, 5, 7)  # one parameter = one chunk
        assert list(par.attrs["col_labels"]) == LABELS[:3]
        assert list(f["parameters/labels"].asstr()[()]) == LABELS[:3]
        assert list(f["parameters/units"].asstr()[()]) == UNITS[:3]
        assert f["stm/times_s"].attrs["units"] == "s"
        deck = f["trajectory_deck"]
        assert deck.attrs["trajectory_hash"] == "ab" * 32
        assert deck.attrs["text_sha256"] == hashlib.sha256(b'title = "t"\n').hexdigest()
    assert missing == []


def test_column_subset_and_reorder_equal_slicing(tmp_path):
    d = _data(7, 4, seed=3)
    path = tmp_path / "s.h5"
    write_stm_file(path, d)
    want = ["arc_t_on[0]", "mu[earth]", "thrust_scale"]
    cols = [LABELS.index(x) for x in want]
    sub = read_stm_file(path, want)
    assert sub.param_labels == want
    assert sub.param_units == [UNITS[c] for c in cols]
    np.testing.assert_array_equal(sub.par_step, d.par_step[:, :, cols])
    np.testing.assert_array_equal(sub.param_values, d.param_values[cols])
    np.testing.assert_array_equal(sub.stm_step, d.stm_step)
    none = read_stm_file(path, [])
    assert none.par_step.shape == (7, 7, 0) and none.param_labels == []


# --------------------------------------------------------------------------- chain


def _loop_chain(d: StmData, idx):
    """Reference: plain left-to-right products over the file steps."""
    out_phi, out_th, prev = [], [], -1
    for i in idx:
        phi, th = np.eye(7), np.zeros((7, d.par_step.shape[2]))
        for s in range(prev + 1, i + 1):
            th = d.stm_step[s] @ th + d.par_step[s]
            phi = d.stm_step[s] @ phi
        out_phi.append(phi)
        out_th.append(th)
        prev = i
    return np.array(out_phi), np.array(out_th)


@settings(max_examples=30, deadline=None)
@given(data=st.data(), seed=st.integers(0, 2**32 - 1))
def test_chain_equals_plain_products(data, seed):
    """1e-13 of the largest entry: at most 12 products of I + 0.1 N entries (norm ~2),
    association order differs, so roundoff ~ 12 eps x growth."""
    d = _data(12, 3, seed)
    idx = sorted(data.draw(st.lists(st.integers(0, 11), min_size=1, max_size=12)))  # repeats allowed
    phi, th = chain(d, d.times_s[idx] + 3e-7)  # within the 1e-6 s matching tolerance
    ref_phi, ref_th = _loop_chain(d, idx)
    assert phi.shape == (len(idx), 7, 7) and th.shape == (len(idx), 7, 3)
    np.testing.assert_allclose(phi, ref_phi, rtol=0, atol=1e-13 * np.abs(ref_phi).max())
    np.testing.assert_allclose(th, ref_th, rtol=0, atol=1e-13 * np.abs(ref_th).max())


def test_chain_element_zero_starts_at_the_epoch():
    """A file whose first time is after the epoch: element 0 includes Phi_0 (epoch -> t_0)."""
    d = _data(4, 2, seed=5, t0=100.0)
    phi, th = chain(d, [d.times_s[0], d.times_s[2]])
    np.testing.assert_array_equal(phi[0], d.stm_step[0])
    np.testing.assert_array_equal(th[0], d.par_step[0])
    ref_phi, _ = _loop_chain(d, [0, 2])
    np.testing.assert_allclose(phi[1], ref_phi[1], rtol=0, atol=1e-14 * np.abs(ref_phi).max())
    with pytest.raises(StmFileError, match=r"times must increase"):
        chain(d, [d.times_s[2], d.times_s[1]])


DECK_SHORT = (
    (ROOT / "namelists" / "leo_j2.toml")
    .read_text()
    .replace("duration_days = 1.0", "duration_days = 0.05")
    .replace("step_days = 0.01 ", "step_days = 0.005")
    .replace('method = "auto"    ', 'method = "rkn4"\nc_nom = 1.0\ndt_max_s = 13.5 ')
    .replace("tolerance = 1e-12 ", "")
)


@pytest.fixture(scope="module")
def leo_run(tmp_path_factory):
    """LEO + J2 for 0.05 d, outputs every 0.005 d (11 times), d/dmu and d/dJ2.  Fixed
    13.5 s steps (dt_max below c_nom r^1.5/sqrt(mu) = 930 s, 32 per output interval), so
    both runs take the same steps whatever their outputs."""
    assert "dt_max_s = 13.5" in DECK_SHORT and "duration_days = 0.05" in DECK_SHORT
    deck = parse_deck(DECK_SHORT, "tests/leo_short.toml")
    prob = dataclasses.replace(build_propagation(deck), param_labels=("mu[earth]", "j2[earth]"))
    assert prob.t_out.shape == (11,)
    traj, sens = propagate_with_sensitivities(
        prob.model, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, prob.t_out, prob.param_labels
    )
    events = ["initial"] + ["grid"] * 9 + ["final"]
    data = stm_data_from_run(prob, traj, sens, events, DECK_SHORT, trajectory_hash(deck), "tests/leo_short.toml")
    path = tmp_path_factory.mktemp("leo") / "leo.h5"
    write_stm_file(path, data)
    return prob, deck, traj, sens, path


def _col_rel(a, b):
    return (np.abs(a - b).max(axis=-2) / np.abs(b).max(axis=-2).clip(1e-300)).max()


def test_stm_data_from_run(leo_run):
    prob, deck, _, _, path = leo_run
    d = read_stm_file(path)
    assert d.primary == ["earth"] * 11 and d.event_types[0] == "initial"
    assert d.param_units == ["km^3/s^2", "1"] and d.sensitivity_method == "ad"
    np.testing.assert_array_equal(d.param_values, [398600.4418, 1.08262668e-3])  # the deck's overrides
    assert np.isnan(d.param_steps).all()
    np.testing.assert_array_equal(d.times_s, prob.t_out)
    np.testing.assert_array_equal(d.stm_step[0], np.eye(7))  # epoch -> times_s[0] = 0
    assert d.deck_hash == trajectory_hash(deck) and d.deck_text == DECK_SHORT


def test_chain_matches_real_propagation(leo_run):
    """Chained file matrices against (a) the generating run's own cumulative matrices
    Phi(t, 0), Theta(t, 0): same products, 1e-12 (roundoff); (b) a second run with
    outputs only at the requested times: 5e-9 per column.  (b) is not roundoff-exact: at
    the conic epoch (t = 0) and at a rectification the AD derivative enters through the
    conic, elsewhere through the Encke deviation, so the two runs differentiate slightly
    different discrete maps; the gap is a truncation error, measured to fall 16x per
    halving of the step (2e-6 at 108 s, 1.3e-7 at 54 s, 8.7e-9 at 27 s, 1.0e-9 here)."""
    prob, _, _, sens, path = leo_run
    idx = [2, 7, 10]
    req = prob.t_out[idx]
    d = read_stm_file(path, ["j2[earth]", "mu[earth]"], times_s=req)
    phi, th = chain(d, req)
    th = th[:, :, ::-1]  # back to (mu, j2), the run's order

    cum_phi, cum_th = np.eye(7), np.zeros((7, 2))
    for j, i in enumerate(idx):
        cum_th = phi[j] @ cum_th + th[j]
        cum_phi = phi[j] @ cum_phi
        assert _col_rel(cum_phi, np.asarray(sens.stm[i])) < 1e-12
        assert _col_rel(cum_th, np.asarray(sens.par[i])) < 1e-12

    # same t_out length (repeating the last time: zero-length segments) -> no recompilation
    t_ref = np.concatenate([[0.0], req, np.full(prob.t_out.shape[0] - 4, req[-1])])
    traj2, sens2 = propagate_with_sensitivities(
        prob.model, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, t_ref, prob.param_labels
    )
    ref_phi, ref_th = np.asarray(sens2.stm_step)[1:4], np.asarray(sens2.par_step)[1:4]
    for j in range(3):
        assert _col_rel(phi[j][:, :6], ref_phi[j][:, :6]) < 5e-9, j
        assert _col_rel(th[j], ref_th[j]) < 5e-9, j
    np.testing.assert_allclose(np.asarray(traj2.x)[1:4], d.states[idx], rtol=0, atol=1e-9)  # km: roundoff


def test_describe(leo_run):
    text = describe(leo_run[4])
    for part in (
        "LEO, Earth point mass + J2",
        "tests/leo_short.toml",
        "2030-01-01T00:00:00.000 TDB",
        "0.050000 d",
        "9 grid",
        "1 initial",
        "1 final",
        "mu[earth]",
        "km^3/s^2",
        "j2[earth]",
        f"schema_version {SCHEMA_VERSION}",
        "KiB",
    ):
        assert part in text, part


def test_stm_data_from_run_refuses_an_early_stop():
    prob = dataclasses.replace(build_propagation(parse_deck(DECK_SHORT, "x.toml")), param_labels=())
    t = prob.t_out.copy()
    t[6:] = np.nan
    nan = np.full((11, 7), np.nan)
    traj = Trajectory(
        t=t,
        x=nan,
        primary=np.zeros(11, np.int32),
        t_final=np.float64(t[5] + 1.0),
        x_final=nan[0],
        primary_final=0,
        status=np.int32(1),
        n_steps=1,
        n_rect=0,
    )
    sens = Sensitivities(*(np.full((11, 7, 7), np.nan),) * 2, *(np.zeros((11, 7, 0)),) * 2)
    with pytest.raises(StmFileError, match=r"^x\.toml: .*stop condition met.*scheduled time 6 at 0\.030000 d"):
        stm_data_from_run(prob, traj, sens, ["grid"] * 11, DECK_SHORT, "h", "x.toml")


# --------------------------------------------------------------------------- trajectory hash


def test_trajectory_hash_ignores_form_but_not_values(tmp_path):
    base = trajectory_hash(parse_deck(DECK_SHORT, "a.toml"))
    assert re.fullmatch(r"[0-9a-f]{64}", base)
    # comments dropped, spacing changed, 7000.0 written 7000, a default (cr = 1) written out
    reformatted = "\n\n".join(
        line.split("#")[0].strip().replace(" = ", "=").replace("7000.0", "7000") for line in DECK_SHORT.splitlines()
    ).replace("[spacecraft]", "[spacecraft]\ncr=1.0")
    assert "cr=1.0" in reformatted  # an explicit default
    moved = tmp_path / "elsewhere" / "renamed.toml"
    moved.parent.mkdir()
    moved.write_text(reformatted)
    from fracas.config.trajectory import load_deck

    assert trajectory_hash(load_deck(moved)) == base
    for old, new in (
        ("7000.0", "7000.001"),
        ("duration_days = 0.05", "duration_days = 0.06"),
        ("LEO, Earth", "LEO: Earth"),
        ("c_nom = 1.0", "c_nom = 0.9"),
    ):
        assert old in DECK_SHORT
        assert trajectory_hash(parse_deck(DECK_SHORT.replace(old, new, 1))) != base, old


def test_check_trajectory(tmp_path):
    d = _data(3, 1)
    check_trajectory(d, "ab" * 32, tmp_path / "s.h5")  # same hash: silent
    with pytest.raises(StmFileError) as err:
        check_trajectory(d, "cd" * 32, tmp_path / "s.h5", study_deck="study.toml")
    msg = str(err.value)
    assert msg.startswith(str(tmp_path / "s.h5")) and "\n" not in msg
    assert "abababababab" in msg and "cdcdcdcdcdcd" in msg and "namelists/t.toml" in msg and "study.toml" in msg


# --------------------------------------------------------------------------- refusals


def _refuses(path, pattern, **kw):
    with pytest.raises(StmFileError) as err:
        read_stm_file(path, **kw)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
    assert re.search(pattern, msg), msg
    return msg


def test_refusals_name_the_file_and_the_problem(tmp_path):
    good = tmp_path / "good.h5"
    write_stm_file(good, _data(4, 2))
    _refuses(tmp_path / "nope.h5", r"no such STM file")
    (tmp_path / "text.h5").write_text("not hdf5")
    _refuses(tmp_path / "text.h5", r"not an HDF5 file")
    with h5py.File(tmp_path / "traj.h5", "w") as f:
        f.attrs["format"] = "fracas-trajectory"
    _refuses(
        tmp_path / "traj.h5", r"not a fracas STM file \(a 'fracas-trajectory' file, expected file_kind = 'fracas-stm'\)"
    )
    _refuses(
        good, r"thrust_scale not on the STM file; it has mu\[earth\], j2\[earth\]", labels=["mu[earth]", "thrust_scale"]
    )
    msg = _refuses(
        good, r"requested time 1000\.000000 s \(0\.011574 d\) is not on the STM file", times_s=[600.0, 1000.0]
    )
    assert "nearest file time is 1200.000000 s (0.013889 d" in msg
    read_stm_file(good, times_s=[600.0 + 9e-7])  # within the 1e-6 s tolerance

    schema = tmp_path / "schema.h5"
    write_stm_file(schema, _data(4, 2))
    with edited(schema) as f:
        f.attrs["schema_version"] = 99
    _refuses(schema, rf"schema_version = 99, this fracas reads {SCHEMA_VERSION}: regenerate with fracas stm build")

    broken = tmp_path / "broken.h5"
    write_stm_file(broken, _data(4, 2))
    with edited(broken) as f:
        del f["stm/stm_step"]
    _refuses(broken, r"stm/stm_step: missing, expected a dataset")
    with pytest.raises(StmFileError, match=re.escape(str(tmp_path / "nope.h5"))):
        describe(tmp_path / "nope.h5")


def test_writer_refuses_inconsistent_data(tmp_path):
    d = _data(4, 2)
    d.par_step = d.par_step[:, :, :1]
    with pytest.raises(StmFileError, match=r"par_step has shape \(4, 7, 1\), expected \(4, 7, 2\)"):
        write_stm_file(tmp_path / "s.h5", d)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_no_partial_file(tmp_path, monkeypatch):
    path = tmp_path / "s.h5"
    write_stm_file(path, _data(3, 1, seed=1))
    before = path.read_bytes()

    def boom(*_a, **_k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr("fracas.io.stm_file.write_provenance", boom)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_stm_file(path, _data(5, 2, seed=2))
    assert path.read_bytes() == before  # the previous file is untouched
    with pytest.raises(RuntimeError):
        write_stm_file(tmp_path / "new.h5", _data(5, 2))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]  # no temporary, no partial file
