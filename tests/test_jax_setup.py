"""fracas._jax: float64 always; the number of XLA host devices is chosen by the process that runs
the work (argument, ``$FRACAS_HOST_DEVICES``, or the caller's own ``XLA_FLAGS``), never one per
core by default.

Each case runs in a fresh subprocess (the device count is fixed once jax starts its CPU
backend), with ``JAX_PLATFORMS=cpu`` and no ``FRACAS_HOST_DEVICES`` / ``XLA_FLAGS`` unless the
case sets them.  The reference is XLA's own default of one CPU device.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_COUNT = "--xla_force_host_platform_device_count"

_REPORT = """
import os, jax, jax.numpy as jnp
assert jnp.ones(1).dtype == jnp.float64 and jax.config.jax_enable_x64
print("DEVICES", jax.device_count(), len(jax.devices("cpu")))
print("XLA_FLAGS", repr(os.environ.get("XLA_FLAGS")))
"""


def _run(code: str, **env_set) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("FRACAS_HOST_DEVICES", "XLA_FLAGS")}
    env["JAX_PLATFORMS"] = "cpu"
    env.update(env_set)
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code) + _REPORT],
        check=False,
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    res = {}
    for line in out.stdout.splitlines():
        key, _, val = line.partition(" ")
        res[key] = val
    n, n_cpu = (int(v) for v in res["DEVICES"].split())
    assert n == n_cpu
    return {"devices": n, "xla_flags": eval(res["XLA_FLAGS"]), "stdout": out.stdout}


def test_plain_import_gives_one_device_and_leaves_xla_flags_alone():
    r = _run("import fracas.integrate.propagate\n")
    assert r["devices"] == 1
    assert r["xla_flags"] is None


def test_a_count_the_caller_put_in_xla_flags_is_kept():
    flags = f"{_COUNT}=2"
    r = _run("import fracas.integrate.batch\n", XLA_FLAGS=flags)
    assert r["devices"] == 2 and r["xla_flags"] == flags


def test_environment_variable():
    r = _run("import fracas.integrate.propagate\n", FRACAS_HOST_DEVICES="2")
    assert r["devices"] == 2
    assert r["xla_flags"] is None  # passed to jax, not to the environment of child processes


def test_environment_variable_wins_over_xla_flags():
    r = _run("import fracas.integrate.propagate\n", FRACAS_HOST_DEVICES="2", XLA_FLAGS=f"{_COUNT}=3")
    assert r["devices"] == 2


def test_configure_with_host_devices_before_the_first_jax_operation():
    r = _run(
        """
        from fracas._jax import configure   # imports jax; its CPU backend starts later
        configure(host_devices=3)
        import fracas.integrate.propagate
        """
    )
    assert r["devices"] == 3 and r["xla_flags"] is None


def test_set_host_devices_before_jax_and_refusal_afterwards():
    r = _run(
        """
        import sys
        assert "jax" not in sys.modules
        import fracas._jax as fj
        fj.set_host_devices(2)
        import jax.numpy as jnp
        jnp.ones(3).block_until_ready()      # the backend has started: the count is fixed
        fj.set_host_devices(2)               # the count it has: fine
        try:
            fj.set_host_devices(4)
        except RuntimeError as e:
            assert "already started with 2 host device" in str(e), e
            print("REFUSED")
        for bad in (0, -1, 1.5, "two", True):
            try:
                fj.set_host_devices(bad)
            except ValueError:
                pass
            else:
                raise AssertionError(bad)
        """
    )
    assert r["devices"] == 2 and "REFUSED" in r["stdout"]


def test_worker_setup_keeps_one_device_even_when_the_environment_asks_for_more():
    r = _run(
        """
        from fracas._jax import worker_setup
        worker_setup()
        import fracas.integrate.batch
        """,
        FRACAS_HOST_DEVICES="4",
    )
    assert r["devices"] == 1


def test_bad_environment_variable_is_a_clear_error():
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS",)}
    env.update(JAX_PLATFORMS="cpu", FRACAS_HOST_DEVICES="many")
    out = subprocess.run(
        [sys.executable, "-c", "import fracas._jax"],
        check=False,
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode != 0 and "FRACAS_HOST_DEVICES" in out.stderr and "'many'" in out.stderr


def test_this_process():
    """The test process itself (conftest imports fracas._jax first) runs in float64."""
    import jax.numpy as jnp

    assert jnp.ones(1).dtype == jnp.float64
