"""Damaged or mis-written files are refused, never used: STM, results, punch and trajectory files.

Reference: a real STM file (LEO + J2, the ``leo_run`` propagation of test_stm_file) and
files written by the writers from small synthetic products; each is copied and corrupted
with h5py (or its bytes), and the reader must refuse it with a one-line error that names
the file and the dataset (and says what was expected).  ``verify=False`` skips only the
SHA-256 checksums: dtype, shape and finiteness are still checked.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from fracas.build import build_propagation
from fracas.build.reference import stm_data_from_run
from fracas.config.trajectory import parse_deck, trajectory_hash
from fracas.errors import DeckError, ResultsFileError, StmFileError
from fracas.integrate.propagate import propagate_with_sensitivities
from fracas.io.hdf5 import CHECKSUM_ATTR, digest_array, provenance, write_strings
from fracas.io.stm_file import SCHEMA_VERSION, read_stm_file, write_stm_file
from fracas.io.team_results import read_punch, read_team_results, write_punch, write_team_results
from fracas.io.trajectory_file import read_trajectory_file, write_trajectory_file
from fracas.products import (
    CovarianceHistory,
    EigenEvents,
    MeasurementLog,
    Prediction,
    TeamProduct,
)
from tests.io.damage import edited, unsealed
from tests.io.test_stm_file import DECK_SHORT
from tests.io.test_trajectory_file import _data as trajectory_data


@pytest.fixture(scope="module")
def stm(tmp_path_factory) -> Path:
    """A real STM file: LEO + J2 for 0.05 d, 11 times, d/dmu and d/dJ2."""
    deck = parse_deck(DECK_SHORT, "tests/leo_short.toml")
    prob = dataclasses.replace(build_propagation(deck), param_labels=("mu[earth]", "j2[earth]"))
    traj, sens = propagate_with_sensitivities(
        prob.model, prob.params, prob.ephem, prob.epoch_et_s, prob.x0, prob.t_out, prob.param_labels
    )
    events = ["initial"] + ["grid"] * 9 + ["final"]
    data = stm_data_from_run(prob, traj, sens, events, DECK_SHORT, trajectory_hash(deck), "tests/leo_short.toml")
    path = tmp_path_factory.mktemp("stm") / "leo.h5"
    write_stm_file(path, data)
    return path


def _copy(src: Path, tmp_path: Path, name: str = "bad.h5") -> Path:
    dst = tmp_path / name
    shutil.copyfile(src, dst)
    return dst


def _replace(f: h5py.File, name: str, data, *, refresh: bool = False) -> None:
    """Replace dataset ``name`` by ``data`` keeping its attributes (``refresh``: and a
    matching checksum, as a writer with a bug would have written it)."""
    attrs = dict(f[name].attrs)
    del f[name]
    ds = f.create_dataset(name, data=data)
    for k, v in attrs.items():
        ds.attrs[k] = v
    if refresh:
        ds.attrs[CHECKSUM_ATTR] = digest_array(np.asarray(data))


def _refused(exc_type, call, path: Path, *patterns: str) -> str:
    with pytest.raises(exc_type) as err:
        call()
    msg = str(err.value)
    assert "\n" not in msg, msg
    assert str(path) in msg, msg
    for pat in patterns:
        assert re.search(pat, msg), (pat, msg)
    return msg


def _stm_refused(path: Path, *patterns: str, **kw) -> str:
    return _refused(StmFileError, lambda: read_stm_file(path, **kw), path, *patterns)


# --------------------------------------------------------------------------- STM file


def test_good_stm_file_reads_with_and_without_verify(stm):
    a, b = read_stm_file(stm), read_stm_file(stm, verify=False)
    np.testing.assert_array_equal(a.stm_step, b.stm_step)
    assert a.schema_version == SCHEMA_VERSION == 2
    with h5py.File(stm, "r") as f:
        assert len(f["stm/par_step"].attrs["column_sha256"]) == 2
        for name in ("stm/times_s", "stm/states", "stm/stm_step", "stm/primary", "parameters/labels"):
            assert len(f[name].attrs[CHECKSUM_ATTR]) == 64, name


def test_string_schema_version(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        f.attrs["schema_version"] = "2"
    _stm_refused(bad, r"schema_version is str \('2'\), expected an integer")


def test_version_1_file_is_refused_with_the_command_that_rebuilds_it(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        f.attrs["schema_version"] = 1
    _stm_refused(bad, r"schema_version = 1, this fracas reads 2: regenerate with fracas stm build")


def test_non_string_file_kind(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        f.attrs["file_kind"] = 7
    _stm_refused(bad, r"file_kind is int64, expected the string 'fracas-stm'")


@pytest.mark.parametrize("verify", [True, False])
def test_string_times(stm, tmp_path, verify):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        t = f["stm/times_s"][()]
        _replace(f, "stm/times_s", np.array([repr(x) for x in t], dtype=object))
    _stm_refused(bad, r"stm/times_s: dtype strings, expected float64", verify=verify)


def test_integer_labels(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        _replace(f, "parameters/labels", np.arange(2))
    _stm_refused(bad, r"parameters/labels: dtype int64, expected UTF-8 strings")


@pytest.mark.parametrize("verify", [True, False])
def test_swapped_step_datasets(stm, tmp_path, verify):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        f.move("stm/stm_step", "stm/tmp")
        f.move("stm/par_step", "stm/stm_step")
        f.move("stm/tmp", "stm/par_step")
    _stm_refused(bad, r"stm/stm_step: shape \(2, 11, 7\), expected \(11, 7, 7\)", verify=verify)


def test_unknown_primary(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        n = f["stm/primary"].shape[0]
        del f["stm/primary"]
        write_strings(f["stm"], "primary", ["vulcan"] * n)  # checksum matches: a writer's bug
    _stm_refused(bad, r"stm/primary: unknown body \['vulcan'\], expected names in fracas.constants.BODIES")


@pytest.mark.parametrize("verify", [True, False])
def test_stm_step_cast_to_int64(stm, tmp_path, verify):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        _replace(f, "stm/stm_step", f["stm/stm_step"][()].astype(np.int64), refresh=True)
    _stm_refused(bad, r"stm/stm_step: dtype int64, expected float64", verify=verify)


def test_par_step_scaled_is_caught_by_the_checksum(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        f["stm/par_step"][...] = f["stm/par_step"][()] * 1e6
    _stm_refused(bad, r"stm/par_step: SHA-256 checksum mismatch \(column 0\)")
    _stm_refused(bad, r"stm/par_step: SHA-256 checksum mismatch \(column 1\)", labels=["j2[earth]"])
    scaled = read_stm_file(bad, verify=False)  # verify=False: the damage goes through (documented)
    np.testing.assert_allclose(scaled.par_step, read_stm_file(stm).par_step * 1e6, rtol=1e-15)


def _flip_stm_step_bit(path: Path) -> None:
    with h5py.File(path, "r") as f:
        ds = f["stm/stm_step"]
        offset = ds.id.get_offset()  # contiguous storage: the raw bytes in the file
        assert offset is not None and ds.chunks is None
    raw = bytearray(path.read_bytes())
    pos = offset + 8 * (3 * 49 + 10)  # stm_step[3, 1, 3], lowest mantissa bit
    raw[pos] ^= 0x01
    path.write_bytes(bytes(raw))


def test_one_flipped_bit_in_stm_step(stm, tmp_path):
    """One flipped mantissa bit: the integrity header refuses the file before h5py opens it;
    in a file without the header (an earlier fracas) the dataset's own SHA-256 names
    stm/stm_step; verify=False decodes either (after the bounded probe) with the one
    changed element."""
    bad = _copy(stm, tmp_path)
    _flip_stm_step_bit(bad)
    _stm_refused(bad, r"damaged file: checksum mismatch \(expected SHA-256 [0-9a-f]{16}\.\.\., got")
    good = read_stm_file(stm)
    assert np.count_nonzero(read_stm_file(bad, verify=False).stm_step != good.stm_step) == 1
    old = tmp_path / "old.h5"
    unsealed(stm, old)
    _flip_stm_step_bit(old)
    _stm_refused(old, r"stm/stm_step: SHA-256 checksum mismatch")
    loose = read_stm_file(old, verify=False)
    assert np.count_nonzero(loose.stm_step != good.stm_step) == 1


@pytest.mark.parametrize("verify", [True, False])
def test_nan_in_states(stm, tmp_path, verify):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        x = f["stm/states"][()]
        x[3, 0] = np.nan
        _replace(f, "stm/states", x, refresh=True)
    _stm_refused(bad, r"stm/states: non-finite value at index \(3, 0\), expected finite numbers", verify=verify)


def test_non_monotonic_times(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        t = f["stm/times_s"][()]
        t[[4, 5]] = t[[5, 4]]
        _replace(f, "stm/times_s", t, refresh=True)
    _stm_refused(bad, r"stm/times_s: decreases at index 5 .* expected non-decreasing")


def test_singular_step_matrix(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        p = f["stm/stm_step"][()]
        p[2] = 0.0
        _replace(f, "stm/stm_step", p, refresh=True)
    _stm_refused(bad, r"stm/stm_step: singular step matrix at index 2")


def test_first_step_not_identity(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        p = f["stm/stm_step"][()]
        p[0] *= 2.0
        _replace(f, "stm/stm_step", p, refresh=True)
    _stm_refused(bad, r"stm/stm_step: stm_step\[0\] is not the identity although times_s\[0\] = 0")


def test_missing_checksum(stm, tmp_path):
    bad = _copy(stm, tmp_path)
    with edited(bad) as f:
        del f["stm/states"].attrs[CHECKSUM_ATTR]
    _stm_refused(bad, r"stm/states: no data_sha256 attribute")
    read_stm_file(bad, verify=False)


def test_truncated_file(stm, tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(stm.read_bytes()[: stm.stat().st_size // 2])
    n = stm.stat().st_size
    _stm_refused(bad, rf"damaged file: {n // 2} bytes, its integrity header says {n} \(truncated after fracas")
    old = tmp_path / "old.h5"
    unsealed(stm, old)
    old.write_bytes(old.read_bytes()[: old.stat().st_size // 2])
    _stm_refused(old, r"unreadable HDF5 file \(damaged or truncated\?\)")


def test_epoch_checked_to_a_microsecond(stm):
    epoch = read_stm_file(stm).epoch_et_s
    read_stm_file(stm, epoch_et_s=epoch + 5e-7)
    _stm_refused(stm, r"stm/epoch_et_s = .* expected the study's epoch", epoch_et_s=epoch + 4600.0)
    _stm_refused(stm, r"stm/epoch_et_s", epoch_et_s=epoch + 2e-6)


# --------------------------------------------------------------------------- results and punch


def _team_product(K: int = 5, n: int = 9, nx: int = 7, seed: int = 0) -> TeamProduct:
    rng = np.random.default_rng(seed)

    def cov(k):
        a = rng.normal(size=(k, n, n))
        return a @ np.swapaxes(a, 1, 2) + n * np.eye(n)

    def hist():
        P = cov(K)
        return CovarianceHistory(
            P_minus=cov(K),
            P_plus=P,
            process_noise=np.zeros((K, nx, nx)),
            sigma=np.sqrt(np.einsum("kii->ki", P)),
            a_priori_sigma=np.ones(n),
            eigen=EigenEvents(
                index=np.array([2], dtype=np.int64),
                position_eigenvalues=np.ones((1, 3)),
                position_eigenvectors=np.eye(3)[None],
                velocity_eigenvalues=np.ones((1, 3)),
                velocity_eigenvectors=np.eye(3)[None],
                correlations=np.eye(n)[None],
            ),
        )

    m = 4
    labels = ["x", "y", "z", "vx", "vy", "vz", "m", "thrust_scale", "mu[sun]"][:n]
    return TeamProduct(
        title="synthetic",
        source="test",
        epoch_et_s=946728000.0,
        times_s=3600.0 * np.arange(K),
        event_types=["initial"] + ["measurement"] * (K - 2) + ["final"],
        states=rng.normal(size=(K, 7)),
        primary=["sun"] * K,
        labels=labels,
        units=["km"] * 3 + ["km/s"] * 3 + ["kg", "1", "km^3/s^2"],
        roles=["state"] * nx + ["solve_for", "consider"],
        n_state=nx,
        assumed=hist(),
        true=hist(),
        measurements=MeasurementLog(
            index=np.arange(m, dtype=np.int64),
            tracking=np.zeros(m, dtype=np.int64),
            kind=["doppler"] * m,
            stations=["goldstone"] * m,
            value=rng.normal(size=m),
            elevation_deg=np.full(m, 30.0),
            used=np.ones(m, dtype=bool),
            sigma=np.full(m, 1e-6),
            innovation_sigma=np.full(m, 2e-6),
        ),
        tracking=[("doppler", "goldstone")],
        predictions=[Prediction(1, 3600.0, 7200.0, cov(1)[0], cov(1)[0])],
        psd_problems=[],
        punch_indices=[K - 1],
        status=0,
        settings={
            "filter": "kalman",
            "propagation": "stm",
            "square_root": False,
            "generalized_covariance": True,
            "reference": "file",
            "trajectory_hash": "ab" * 32,
        },
        provenance=provenance("x = 1\n", "d.toml"),
    )


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("res")
    prod = _team_product()
    write_team_results(d / "r.h5", prod)
    write_punch(d / "p.h5", prod)
    return d / "r.h5", d / "p.h5"


def test_good_results_and_punch_read(results):
    r = read_team_results(results[0])
    assert r["assumed"]["P_plus"].shape == (5, 9, 9) and len(r["labels"]) == 9
    p = read_punch(results[1])
    assert p["assumed"].shape == (9, 9) and p["labels"] == ["thrust_scale", "mu[sun]"]


def test_results_string_times(results, tmp_path):
    bad = _copy(results[0], tmp_path)
    with edited(bad) as f:
        _replace(f, "team/times_s", np.array(["0", "1", "2", "3", "4"], dtype=object))
    _refused(ResultsFileError, lambda: read_team_results(bad), bad, r"team/times_s: dtype strings, expected float64")


def test_results_scaled_sigma_is_caught_by_the_checksum(results, tmp_path):
    bad = _copy(results[0], tmp_path)
    with edited(bad) as f:
        f["team/assumed/sigma"][...] = f["team/assumed/sigma"][()] * 1e3
    _refused(ResultsFileError, lambda: read_team_results(bad), bad, r"team/assumed/sigma: SHA-256 checksum mismatch")
    read_team_results(bad, verify=False)


def test_results_inconsistent_shapes_and_missing_datasets(results, tmp_path):
    bad = _copy(results[0], tmp_path)
    with edited(bad) as f:
        _replace(f, "team/true/P_plus", f["team/true/P_plus"][()][:, :8, :8], refresh=True)
    _refused(
        ResultsFileError,
        lambda: read_team_results(bad, verify=False),
        bad,
        r"team/true/P_plus: shape \(5, 8, 8\), expected \(5, 9, 9\)",
    )
    gone = _copy(results[0], tmp_path, "gone.h5")
    with edited(gone) as f:
        del f["team/labels/units"]
    _refused(ResultsFileError, lambda: read_team_results(gone), gone, r"team/labels/units: missing")


def test_results_schema_version_string_and_schema_1_without_checksums(results, tmp_path):
    bad = _copy(results[0], tmp_path)
    with edited(bad) as f:
        f.attrs["schema_version"] = "2"
    _refused(ResultsFileError, lambda: read_team_results(bad), bad, r"schema_version is str")
    old = _copy(results[0], tmp_path, "old.h5")
    with edited(old) as f:  # a schema-1 file: no checksums, still read
        f.attrs["schema_version"] = 1
        f.visititems(lambda _n, o: o.attrs.__delitem__(CHECKSUM_ATTR) if CHECKSUM_ATTR in o.attrs else None)
    assert read_team_results(old)["labels"] == read_team_results(results[0])["labels"]
    with edited(old) as f:
        f.attrs["schema_version"] = 2  # claims checksums but has none
    _refused(ResultsFileError, lambda: read_team_results(old), old, r"no data_sha256 attribute")


def test_punch_damage_is_a_deck_error_naming_the_dataset(results, tmp_path):
    bad = _copy(results[1], tmp_path)
    with edited(bad) as f:
        f["punch_000/assumed"][0, 0] = 1e9
    _refused(DeckError, lambda: read_punch(bad, "study.toml"), bad, r"^study.toml: ", r"punch_000/assumed: SHA-256")
    asym = _copy(results[1], tmp_path, "asym.h5")
    with edited(asym) as f:
        a = f["punch_000/assumed"][()]
        a[0, 1] += 1.0
        _replace(f, "punch_000/assumed", a, refresh=True)
    _refused(DeckError, lambda: read_punch(asym), asym, r"punch_000/assumed: not symmetric")
    small = _copy(results[1], tmp_path, "small.h5")
    with edited(small) as f:
        _replace(f, "punch_000/assumed", f["punch_000/assumed"][()][:8, :8], refresh=True)
    _refused(DeckError, lambda: read_punch(small, verify=False), small, r"shape \(8, 8\), expected \(9, 9\)")
    ints = _copy(results[1], tmp_path, "ints.h5")
    with edited(ints) as f:
        _replace(f, "punch_000/time_s", np.int64(3))
    _refused(DeckError, lambda: read_punch(ints), ints, r"punch_000/time_s: dtype int64, expected float64")


# --------------------------------------------------------------------------- trajectory file


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory) -> Path:
    return write_trajectory_file(tmp_path_factory.mktemp("traj") / "t.h5", trajectory_data())


def _traj_refused(path, *patterns, **kw):
    return _refused(StmFileError, lambda: read_trajectory_file(path, **kw), path, *patterns)


def test_trajectory_string_times(trajectory, tmp_path):
    bad = _copy(trajectory, tmp_path)
    with edited(bad) as f:
        _replace(f, "trajectory/t_s", np.array(["0"] * 5, dtype=object))
    _traj_refused(bad, r"trajectory/t_s: dtype strings, expected float64", verify=False)


def test_trajectory_scaled_positions_and_flipped_sensitivities(trajectory, tmp_path):
    bad = _copy(trajectory, tmp_path)
    with edited(bad) as f:
        f["trajectory/r_km"][...] = f["trajectory/r_km"][()] * 1e3
        f["sensitivities/stm"][0, 0, 0] = -f["sensitivities/stm"][0, 0, 0]
    _traj_refused(bad, r"sensitivities/stm: SHA-256 checksum mismatch")
    with edited(bad) as f:
        f["sensitivities/stm"][0, 0, 0] = -f["sensitivities/stm"][0, 0, 0]
    _traj_refused(bad, r"trajectory/r_km: SHA-256 checksum mismatch")
    read_trajectory_file(bad, verify=False)


def test_trajectory_inconsistent_shapes(trajectory, tmp_path):
    bad = _copy(trajectory, tmp_path)
    with edited(bad) as f:
        _replace(f, "trajectory/v_km_s", f["trajectory/v_km_s"][()][:4], refresh=True)
    _traj_refused(bad, r"trajectory/v_km_s: shape \(4, 3\), expected \(5, 3\)")
    with edited(bad) as f:
        _replace(f, "trajectory/v_km_s", np.zeros((5, 3)), refresh=True)
        _replace(f, "sensitivities/par_step", np.zeros((5, 7, 3)), refresh=True)
    _traj_refused(bad, r"sensitivities/par_step: shape \(5, 7, 3\), expected \(5, 7, 2\)")
