"""fracas.integrate.batch: a vmapped, chunked (padded) and sharded batch of propagations equals
the same propagations run one at a time.

Reference: :func:`fracas.integrate.propagate.propagate` (and ``propagate_with_sensitivities``)
called once per initial state.  Batched code may fuse differently, so equality is checked to
1e-12 relative (position and velocity norms) rather than bit for bit; step counts, status
and the number of rectifications must match exactly.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from fracas.dynamics.model import ForceModel, IntegratorSettings, default_params
from fracas.integrate.batch import chunk_rows, host_devices, propagate_batch
from fracas.integrate.propagate import propagate, propagate_with_sensitivities

ROOT = Path(__file__).resolve().parents[2]
MODEL = ForceModel(bodies=("earth",), j2=True, integrator=IntegratorSettings(c_nom=0.05, dt_max_s=4000.0))
PARAMS = default_params(MODEL, mu=[398600.4418], j2=[1.08262668e-3], radius=[6378.137], pole=[[0, 0, 1.0]])
T_OUT = np.array([0.0, 2500.0, 6000.0])


def _states(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x0 = np.tile(np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 1.0, 1000.0]), (n, 1))
    x0[:, :3] += rng.normal(0.0, 100.0, (n, 3))
    x0[:, 3:6] += rng.normal(0.0, 0.02, (n, 3))
    return x0


def _close_states(a, b, rtol=1e-12):
    """|dr| <= rtol |r| and |dv| <= rtol |v| and |dm| <= rtol m, row by row (any leading axes)."""
    a, b = np.asarray(a), np.asarray(b)
    for sl in (slice(0, 3), slice(3, 6), slice(6, 7)):
        d = np.linalg.norm(a[..., sl] - b[..., sl], axis=-1)
        s = np.linalg.norm(b[..., sl], axis=-1)
        assert np.all(d <= rtol * s), (d / s).max()


def _check_traj(tr_batch, i, tr_one):
    _close_states(tr_batch.x[i], tr_one.x)
    _close_states(tr_batch.x_final[i], tr_one.x_final)
    np.testing.assert_array_equal(tr_batch.t[i], np.asarray(tr_one.t))
    assert int(tr_batch.n_steps[i]) == int(tr_one.n_steps)
    assert int(tr_batch.n_rect[i]) == int(tr_one.n_rect)
    assert int(tr_batch.status[i]) == int(tr_one.status) == 0


def test_chunk_rows():
    """Small batches round up to a power of two (few compiled shapes for many batch sizes),
    large ones use the chunk size; always a multiple of the device count."""
    assert chunk_rows(5, 4096, 1) == 8
    assert chunk_rows(5, 4096, 2) == 8
    assert chunk_rows(8, 4096, 1) == 8
    assert chunk_rows(9, 4096, 1) == 16
    assert chunk_rows(3000, 2048, 1) == 2048
    assert chunk_rows(10_000, 4096, 2) == 4096
    assert chunk_rows(10_000, 1001, 2) == 1002
    assert chunk_rows(3, 2, 1) == 2
    assert chunk_rows(1, 1024, 2) == 2


@pytest.mark.slow  # ~25 s of a cold make test (mostly XLA compilation; issue 22)
def test_grouped_lanes_come_back_in_the_callers_order():
    """group_lanes sorts the lanes by their expected step count before chunking; each output
    row is still the propagation of the caller's row (the same numbers as ungrouped)."""
    x0s = _states(6)
    x0s[::2, :3] *= 1.3  # alternate two orbit sizes so sorting permutes the rows
    plain = propagate_batch(MODEL, PARAMS, None, 0.0, x0s, T_OUT, chunk_size=2, devices=host_devices()[:1])
    grouped = propagate_batch(
        MODEL, PARAMS, None, 0.0, x0s, T_OUT, chunk_size=2, devices=host_devices()[:1], group_lanes=True
    )
    np.testing.assert_array_equal(grouped.x, plain.x)
    np.testing.assert_array_equal(grouped.n_steps, plain.n_steps)


def test_batch_of_five_equals_five_single_propagations():
    x0s = _states(5)
    tr = propagate_batch(MODEL, PARAMS, None, 0.0, x0s, T_OUT, devices=host_devices()[:1])
    assert tr.x.shape == (5, len(T_OUT), 7) and tr.x_final.shape == (5, 7)
    assert isinstance(tr.x, np.ndarray)
    for i in range(5):
        _check_traj(tr, i, propagate(MODEL, PARAMS, None, 0.0, x0s[i], T_OUT))


def test_chunking_with_padding_gives_the_same_results():
    x0s = _states(5, seed=1)
    whole = propagate_batch(MODEL, PARAMS, None, 0.0, x0s, T_OUT, devices=host_devices()[:1])
    # chunks of 2 rows: (0,1) (2,3) (4, pad); the padded row must not leak into the outputs
    seen = []
    chunked = propagate_batch(
        MODEL,
        PARAMS,
        None,
        0.0,
        x0s,
        T_OUT,
        chunk_size=2,
        devices=host_devices()[:1],
        progress=lambda done, total: seen.append((done, total)),
    )
    assert seen == [(2, 5), (4, 5), (5, 5)]  # one progress report per chunk, padding not counted
    assert chunked.x.shape == whole.x.shape
    _close_states(chunked.x, whole.x)
    np.testing.assert_array_equal(chunked.n_steps, whole.n_steps)
    np.testing.assert_array_equal(chunked.status, whole.status)


@pytest.mark.slow  # ~25 s of a cold make test (mostly XLA compilation; issue 22)
def test_batched_params_match_single_propagations():
    x0s = _states(3, seed=2)
    mus = np.array([[398600.4418], [398600.0], [398601.0]])
    p = PARAMS._replace(mu=mus)
    tr = propagate_batch(
        MODEL, p, None, 0.0, x0s, T_OUT, chunk_size=2, params_axes={"mu": 0}, devices=host_devices()[:1]
    )
    for i in range(3):
        one = propagate(MODEL, PARAMS._replace(mu=mus[i]), None, 0.0, x0s[i], T_OUT)
        _check_traj(tr, i, one)
    with pytest.raises(ValueError):
        propagate_batch(MODEL, p, None, 0.0, x0s[:2], T_OUT, params_axes={"mu": 0})
    with pytest.raises(KeyError):
        propagate_batch(MODEL, p, None, 0.0, x0s, T_OUT, params_axes={"nope": 0})


@pytest.mark.slow  # the batched AD program (~45 s cold); batched plain propagations stay in make test
def test_batched_sensitivities_match_single():
    x0s = _states(3, seed=3)
    t_out = np.array([0.0, 3000.0])
    labels = ("mu[earth]",)
    tr, sens = propagate_batch(
        MODEL,
        PARAMS,
        None,
        0.0,
        x0s,
        t_out,
        chunk_size=2,
        with_sensitivities=True,
        param_labels=labels,
        devices=host_devices()[:1],
    )
    assert sens.stm.shape == (3, 2, 7, 7) and sens.par.shape == (3, 2, 7, 1)
    for i in range(3):
        tr1, s1 = propagate_with_sensitivities(MODEL, PARAMS, None, 0.0, x0s[i], t_out, labels)
        _check_traj(tr, i, tr1)
        for a, b in ((sens.stm[i], s1.stm), (sens.par[i], s1.par)):
            b = np.asarray(b)
            assert np.max(np.abs(a - b)) <= 1e-11 * np.max(np.abs(b))


@pytest.mark.slow
def test_sharded_over_two_host_devices_matches_one_device():
    """In a subprocess with two host devices (``FRACAS_HOST_DEVICES=2``: the count is fixed when
    jax starts its CPU backend, and a process has one device by default)."""
    code = textwrap.dedent(
        """
        import numpy as np, jax
        from tests.integrate.test_batch import MODEL, PARAMS, T_OUT, _states, _close_states
        from fracas.integrate.batch import propagate_batch, host_devices
        devs = host_devices()
        assert len(devs) == 2, devs
        x0s = _states(5, seed=4)
        two = propagate_batch(MODEL, PARAMS, None, 0.0, x0s, T_OUT, chunk_size=4)
        one = propagate_batch(MODEL, PARAMS, None, 0.0, x0s, T_OUT, devices=devs[:1])
        _close_states(two.x, one.x)
        np.testing.assert_array_equal(two.n_steps, one.n_steps)
        print("OK")
        """
    )
    env = dict(os.environ)
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    env["XLA_FLAGS"] = " ".join(flags)
    env["FRACAS_HOST_DEVICES"] = "2"
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0 and "OK" in out.stdout, out.stdout + out.stderr
