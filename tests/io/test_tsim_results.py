"""TSIM results and checkpoint files: exact round trip, one-line refusals of missing,
foreign, other-kind and damaged files, the checkpoint's plan-key guard."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from fracas.errors import FracasError, ResultsFileError
from fracas.io.tsim_results import (
    read_tsim_checkpoint,
    read_tsim_results,
    tsim_statistics,
    write_tsim_checkpoint,
    write_tsim_results,
)
from fracas.products import TsimManeuver, TsimProduct
from tests.io.damage import edited


def synthetic_product(n: int = 200, seed: int = 7) -> TsimProduct:
    """200 missions, an impulsive and a primary maneuver (3 controls each), 3 final targets."""
    rng = np.random.default_rng(seed)
    J, nx, m = 2, 7, 3
    status = np.zeros(n, np.int32)
    status[rng.choice(n, 6, replace=False)] = [1, 1, 2, 2, 3, 1]
    failed = np.where(status >= 2, rng.integers(0, J, n), -1).astype(np.int32)
    team_cov = np.diag([4.0, 9.0, 1.0])
    te = rng.multivariate_normal(np.zeros(m), team_cov * 1.1, n)
    dv = np.abs(rng.normal(0.002, 0.001, (n, J)))
    table = {
        "mission": np.arange(n, dtype=np.int64),
        "status": status,
        "failed_maneuver": failed,
        "iterations": rng.integers(1, 5, (n, J)).astype(np.int32),
        "initial_deviation": rng.normal(size=(n, nx)),
        "state_deviation": rng.normal(size=(n, J, 7)),
        "knowledge_error": rng.normal(size=(n, J, nx)),
        "correction": rng.normal(size=(n, J, 3)),
        "execution_error": rng.normal(size=(n, J, 3)) * 1e-3,
        "dv_km_s": dv,
        "dv_total_km_s": dv.sum(axis=1),
        "target_error": te,
        "maneuver_status": rng.integers(0, 3, size=(n, J)).astype(np.int32),
        "final_mass_kg": 1000.0 - rng.random(n),
    }
    good = status <= 1
    labels = ["x", "y", "z", "vx", "vy", "vz", "m"]
    mans = [
        TsimManeuver(
            name="TCM1",
            type="impulsive",
            law="linear",
            time_s=86400.0,
            control_labels=["dv_x", "dv_y", "dv_z"],
            control_units=["km/s"] * 3,
            target_names=["x", "y", "z"],
            target_units=["km"] * 3,
            target_time_s=864000.0,
            team_correction_cov=np.diag([1e-6, 2e-6, 3e-6]),
            team_dv_mean_km_s=0.0021,
            team_dv_99_km_s=0.0045,
            team_target_cov_after=np.diag([2.0, 3.0, 4.0]),
        ),
        TsimManeuver(
            name="arc/2",
            type="primary",
            law="nonlinear",
            time_s=172800.0,
            control_labels=["ra", "dec", "dt"],
            control_units=["deg", "deg", "s"],
            target_names=["x", "y", "z"],
            target_units=["km"] * 3,
            target_time_s=864000.0,
            team_correction_cov=np.diag([0.1, 0.2, 30.0]),
            team_dv_mean_km_s=0.0019,
            team_dv_99_km_s=0.004,
            team_target_cov_after=team_cov,
            failures=2,
            near=3,
        ),
    ]
    stats = {
        "target_error": (int(good.sum()), te[good].mean(axis=0), np.cov(te[good], rowvar=False)),
        "dv_km_s[TCM1]": (int(good.sum()), np.array([dv[good, 0].mean()]), np.array([[dv[good, 0].var()]])),
        "dv_km_s[arc/2]": (int(good.sum()), np.array([dv[good, 1].mean()]), np.array([[dv[good, 1].var()]])),
    }
    pct = {"dv_km_s[TCM1]": {50.0: 0.002, 90.0: 0.003, 99.0: 0.0044}, "dv_total_km_s": {50: 0.004, 99: 0.008}}
    consistency = [
        {
            "output": "target_error",
            "names": ["x", "y", "z"],
            "units": ["km", "km", "km"],
            "count": int(good.sum()),
            "ratio": [1.04, 1.06, 1.02],
            "se": 0.05,
            "chi2": 5.1,
            "dof": 6,
            "p_value": 0.53,
            "mean_chi2": 1.2,
            "mean_p_value": 0.75,
            "coverage": [[1, 0.19, 0.199, 0.028], [2, 0.72, 0.738, 0.031], [3, 0.97, 0.971, 0.012]],
            "verdict": "consistent",
            "message": "target_error: TSIM dispersion consistent with TEAM (sigma ratios 1.02-1.06, p = 0.53)",
        },
        {
            "output": "dv_km_s[arc/2]",
            "names": ["dv"],
            "units": ["km/s"],
            "count": 0,
            "ratio": [float("nan")],
            "se": float("nan"),
            "chi2": float("nan"),
            "dof": 0,
            "p_value": float("nan"),
            "mean_chi2": float("nan"),
            "mean_p_value": float("nan"),
            "coverage": [],
            "verdict": "not compared",
            "message": "dv_km_s[arc/2]: not compared (a nonlinear maneuver's |dV| has no Gaussian TEAM prediction)",
        },
    ]
    counts = {"missions": n, "ok": int((status == 0).sum()), "near": 3, "hopeless": 2, "failed": 1, "a_priori": 0}
    return TsimProduct(
        title="synthetic TSIM",
        source="decks/synthetic.toml",
        epoch_et_s=6.5e8,
        labels=labels,
        n_state=7,
        maneuvers=mans,
        final_target_names=["x", "y", "z"],
        final_target_units=["km"] * 3,
        final_target_time_s=864000.0,
        team_target_cov=team_cov,
        table=table,
        statistics=stats,
        percentiles=pct,
        consistency=consistency,
        counts=counts,
        settings={"seed": 11, "first_mission": 0, "missions": n, "scale": 1.0, "sampling": "random", "block": 64},
        timing={"total_s": 1.5, "missions_s": 1.2},
        provenance={"fracas_version": "0.0", "deck_path": "decks/synthetic.toml", "deck_text": "[tsim]\n"},
    )


@pytest.fixture(scope="module")
def product() -> TsimProduct:
    return synthetic_product()


@pytest.fixture(scope="module")
def written(product, tmp_path_factory):
    p = tmp_path_factory.mktemp("tsim") / "run.tsim.h5"
    write_tsim_results(p, product)
    return p


def _same(a, b) -> bool:
    """Equality with NaN == NaN, for the JSON rows."""
    if isinstance(a, float) and isinstance(b, float):
        return (np.isnan(a) and np.isnan(b)) or a == b
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, list) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def test_round_trip_exact(product, written):
    back = read_tsim_results(written)
    for key in ("title", "source", "epoch_et_s", "labels", "n_state", "final_target_names", "final_target_units"):
        assert getattr(back, key) == getattr(product, key), key
    assert back.final_target_time_s == product.final_target_time_s
    np.testing.assert_array_equal(back.team_target_cov, product.team_target_cov)
    assert list(back.table) == list(product.table)
    for key, arr in product.table.items():
        assert back.table[key].dtype == arr.dtype, key
        np.testing.assert_array_equal(back.table[key], arr, err_msg=key)
    assert len(back.maneuvers) == len(product.maneuvers)
    for a, b in zip(product.maneuvers, back.maneuvers):
        for f in ("name", "type", "law", "time_s", "control_labels", "control_units", "target_names"):
            assert getattr(a, f) == getattr(b, f), f
        for f in ("target_units", "target_time_s", "team_dv_mean_km_s", "team_dv_99_km_s", "failures", "near"):
            assert getattr(a, f) == getattr(b, f), f
        np.testing.assert_array_equal(a.team_correction_cov, b.team_correction_cov)
        np.testing.assert_array_equal(a.team_target_cov_after, b.team_target_cov_after)
    assert list(back.statistics) == list(product.statistics)
    for name, (count, mean, cov) in product.statistics.items():
        c2, m2, v2 = back.statistics[name]
        assert c2 == count and isinstance(c2, int)
        np.testing.assert_array_equal(m2, mean)
        np.testing.assert_array_equal(v2, cov)
    assert back.percentiles == product.percentiles
    assert _same(product.consistency, back.consistency)
    assert back.counts == product.counts
    assert back.settings == product.settings
    assert back.timing == product.timing
    for key, val in product.provenance.items():
        assert back.provenance[key] == val


def test_statistics_only(product, written):
    n_ok, stats = tsim_statistics(written)
    c = product.counts
    assert n_ok == c["ok"] + c["near"] + c["a_priori"]
    assert list(stats) == list(product.statistics)
    np.testing.assert_array_equal(stats["target_error"][2], product.statistics["target_error"][2])


def _one_line(exc: pytest.ExceptionInfo, path, *words) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    assert str(path) in msg
    for w in words:
        assert w in msg, (w, msg)
    assert isinstance(exc.value, FracasError)
    return msg


def test_missing_file(tmp_path):
    p = tmp_path / "nope.h5"
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p)
    _one_line(exc, p, "no such")


def test_not_hdf5(tmp_path):
    p = tmp_path / "junk.h5"
    p.write_text("not an HDF5 file\n")
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p)
    _one_line(exc, p, "HDF5")


def test_other_kind(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f.attrs["file_kind"] = "fracas-tom-results"
        f.attrs["schema_version"] = 1
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p)
    _one_line(exc, p, "fracas-tsim-results", "fracas-tom-results")


@pytest.mark.parametrize(
    "dataset",
    [
        "tsim/missions/dv_km_s",
        "tsim/missions/status",
        "tsim/final/team_target_cov",
        "tsim/maneuvers/1_arc|2/team_dv_99_km_s",
        "tsim/statistics/target_error/covariance",
        "tsim/consistency",
        "tsim/counts",
    ],
)
def test_dataset_deleted(written, tmp_path, dataset):
    p = tmp_path / "damaged.h5"
    p.write_bytes(written.read_bytes())
    with edited(p, "a") as f:
        del f[dataset]
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p)
    _one_line(exc, p, dataset, "expected")


def test_edited_and_bad_json(written, tmp_path):
    p = tmp_path / "edited.h5"
    p.write_bytes(written.read_bytes())
    with edited(p, "a") as f:
        f["tsim/missions/final_mass_kg"][0] = 1.0
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p)
    _one_line(exc, p, "tsim/missions/final_mass_kg", "checksum")
    q = tmp_path / "json.h5"
    q.write_bytes(written.read_bytes())
    with edited(q, "a") as f:
        del f["tsim/settings"]
        f.create_dataset("tsim/settings", data="{not json", dtype=h5py.string_dtype())
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(q, verify=False)
    _one_line(exc, q, "tsim/settings", "JSON")


def test_wrong_shape(written, tmp_path):
    p = tmp_path / "shape.h5"
    p.write_bytes(written.read_bytes())
    with edited(p, "a") as f:
        del f["tsim/missions/target_error"]
        f["tsim/missions/target_error"] = np.zeros((200, 2))
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_results(p, verify=False)
    _one_line(exc, p, "tsim/missions/target_error", "shape", "(200, 3)")


def _blocks(rng):
    return {
        k: {
            "mission": np.arange(8 * k, 8 * k + 8, dtype=np.int64),
            "status": np.zeros(8, np.int32),
            "dv_km_s": rng.random((8, 2)),
            "target_error": rng.normal(size=(8, 3)),
        }
        for k in (0, 1, 3)
    }


def test_checkpoint_round_trip(tmp_path):
    p = tmp_path / "run.ckpt.h5"
    assert read_tsim_checkpoint(p, "abc") == {}
    blocks = _blocks(np.random.default_rng(3))
    write_tsim_checkpoint(p, "abc", {k: blocks[k] for k in (0, 1)})
    write_tsim_checkpoint(p, "abc", blocks)  # rewrites the whole file
    back = read_tsim_checkpoint(p, "abc")
    assert list(back) == [0, 1, 3]
    for k, arrays in blocks.items():
        assert back[k].keys() == arrays.keys()
        for name, arr in arrays.items():
            assert back[k][name].dtype == arr.dtype
            np.testing.assert_array_equal(back[k][name], arr)
    assert not [x for x in tmp_path.iterdir() if x.name.endswith(".tmp")]


def test_checkpoint_other_run_and_damage(tmp_path):
    p = tmp_path / "run.ckpt.h5"
    write_tsim_checkpoint(p, "abc", _blocks(np.random.default_rng(4)))
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_checkpoint(p, "xyz")
    _one_line(exc, p, "different run")
    with edited(p, "a") as f:
        del f["block_1/dv_km_s"]
        f["block_1/dv_km_s"] = np.zeros((8, 2))
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_checkpoint(p, "abc")
    _one_line(exc, p, "block_1/dv_km_s")
    q = tmp_path / "junk.ckpt.h5"
    q.write_bytes(b"\x00garbage")
    with pytest.raises(ResultsFileError) as exc:
        read_tsim_checkpoint(q, "abc")
    _one_line(exc, q, "HDF5")
