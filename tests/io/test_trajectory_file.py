"""The trajectory file: exact round trip, units on every dataset, atomic writes."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fracas.errors import StmFileError
from fracas.io import hdf5
from fracas.io.hdf5 import atomic_h5, provenance
from fracas.io.trajectory_file import (
    FORMAT,
    SCHEMA_VERSION,
    SensitivityData,
    TrajectoryData,
    read_trajectory_file,
    write_trajectory_file,
)

DECK = 'title = "x"\n[epoch]\niso = "2030-01-01"\n'


def _data(n: int = 5, n_par: int = 2, seed: int = 1, sens: bool = True, early_stop: bool = False) -> TrajectoryData:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 86400.0, n)
    prim = ["earth"] * n
    if early_stop and n > 1:
        t[-1] = np.nan
        prim[-1] = ""
    labels = tuple(["mu[earth]", "j2[earth]", "thrust_scale"][:n_par])
    units = tuple(["km^3/s^2", "1", "1"][:n_par])
    s = None
    if sens:
        s = SensitivityData(
            stm=rng.normal(size=(n, 7, 7)),
            stm_step=rng.normal(size=(n, 7, 7)),
            par=rng.normal(size=(n, 7, n_par)),
            par_step=rng.normal(size=(n, 7, n_par)),
            param_labels=labels,
            param_units=units,
        )
    return TrajectoryData(
        epoch_et_s=946728000.0,
        t_s=t,
        r_km=rng.normal(size=(n, 3)) * 7000.0,
        v_km_s=rng.normal(size=(n, 3)),
        mass_kg=1000.0 - rng.random(n),
        primary=tuple(prim),
        bodies=("sun", "earth", "moon"),
        t_final_s=86400.0,
        r_final_km=rng.normal(size=3),
        v_final_km_s=rng.normal(size=3),
        mass_final_kg=999.5,
        primary_final="earth",
        status=1 if early_stop else 0,
        n_steps=1234,
        n_rect=17,
        centre="earth",
        title="a test [trajectory]",
        epoch_tdb="2030-01-01T00:00:00.000",
        sensitivities=s,
        provenance=provenance(DECK, "namelists/x.toml"),
    )


def _assert_same(a: TrajectoryData, b: TrajectoryData) -> None:
    for name in ("t_s", "r_km", "v_km_s", "mass_kg", "r_final_km", "v_final_km_s"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))  # bit-exact float64
    for name in (
        "epoch_et_s",
        "t_final_s",
        "mass_final_kg",
        "primary",
        "bodies",
        "primary_final",
        "status",
        "n_steps",
        "n_rect",
        "centre",
        "title",
        "epoch_tdb",
    ):
        assert getattr(a, name) == getattr(b, name), name
    assert (a.sensitivities is None) == (b.sensitivities is None)
    if a.sensitivities is not None:
        for name in ("stm", "stm_step", "par", "par_step"):
            np.testing.assert_array_equal(getattr(a.sensitivities, name), getattr(b.sensitivities, name))
        assert a.sensitivities.param_labels == b.sensitivities.param_labels
        assert a.sensitivities.param_units == b.sensitivities.param_units
    assert a.provenance == b.provenance


def test_round_trip(tmp_path):
    d = _data()
    path = write_trajectory_file(tmp_path / "sub" / "t.h5", d)
    assert path == tmp_path / "sub" / "t.h5"
    _assert_same(d, read_trajectory_file(path))


@settings(max_examples=15, deadline=None)
@given(
    n=st.integers(1, 30),
    n_par=st.integers(0, 3),
    seed=st.integers(0, 2**32 - 1),
    sens=st.booleans(),
    early=st.booleans(),
)
def test_round_trip_is_identity(tmp_path_factory, n, n_par, seed, sens, early):
    d = _data(n, n_par, seed, sens, early)
    path = write_trajectory_file(tmp_path_factory.mktemp("rt") / "t.h5", d)
    _assert_same(d, read_trajectory_file(path))


def test_every_dataset_has_units_and_layout(tmp_path):
    path = write_trajectory_file(tmp_path / "t.h5", _data())
    missing = []
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == FORMAT
        assert int(f.attrs["schema_version"]) == SCHEMA_VERSION == 2
        assert {"trajectory", "sensitivities", "provenance"} <= set(f)

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and "units" not in obj.attrs:
                missing.append(name)

        f.visititems(visit)
        assert f["trajectory/r_km"].attrs["units"] == "km"
        assert f["trajectory/v_km_s"].attrs["units"] == "km/s"
        assert f["trajectory/t_s"].attrs["units"] == "s"
        par = f["sensitivities/par"]
        assert list(par.attrs["col_labels"]) == ["mu[earth]", "j2[earth]"]
        assert list(par.attrs["row_units"]) == ["km", "km", "km", "km/s", "km/s", "km/s", "kg"]
        assert list(f["trajectory/primary_index"][()]) == [1] * 5
        g = f["provenance"]
        assert g.attrs["deck_sha256"] == hashlib.sha256(DECK.encode()).hexdigest()
        assert g["deck_text"].asstr()[()] == DECK
        assert "jax" in g["libraries"].attrs and "numpy" in g["libraries"].attrs
    assert missing == []


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_failed_write_leaves_no_partial_file(tmp_path, monkeypatch):
    def boom(*_a, **_k):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr("fracas.io.trajectory_file.write_provenance", boom)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_trajectory_file(tmp_path / "t.h5", _data())
    assert _leftovers(tmp_path) == []  # neither the file nor its temporary


def test_failed_write_keeps_previous_file(tmp_path, monkeypatch):
    old = _data(seed=7)
    path = write_trajectory_file(tmp_path / "t.h5", old)
    before = path.read_bytes()

    def boom(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("fracas.io.trajectory_file.write_provenance", boom)
    with pytest.raises(StmFileError, match=r"t\.h5: cannot write the trajectory file: No space left on device"):
        write_trajectory_file(path, _data(seed=8))
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == ["t.h5"]
    _assert_same(old, read_trajectory_file(path))


def test_atomic_h5_fsyncs_and_replaces(tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(hdf5.os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd)))
    with atomic_h5(tmp_path / "a.h5") as f:
        f["x"] = np.arange(3)
        assert not (tmp_path / "a.h5").exists()  # invisible until complete
    assert synced
    with h5py.File(tmp_path / "a.h5", "r") as f:
        assert list(f["x"][()]) == [0, 1, 2]


def test_read_errors(tmp_path):
    with pytest.raises(StmFileError, match="no such file"):
        read_trajectory_file(tmp_path / "none.h5")
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    with pytest.raises(StmFileError, match="not a fracas trajectory file"):
        read_trajectory_file(other)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(StmFileError, match=r"not an HDF5 file \(no HDF5 signature; damaged\?\)"):
        read_trajectory_file(junk)


def test_summary_dict_is_json(tmp_path):
    import json

    d = _data()
    s = json.loads(json.dumps(d.summary_dict()))
    assert s["status"] == 0 and s["primary"] == "earth" and len(s["r_km"]) == 3
