"""One place that configures JAX: float64 everywhere, the persistent compilation cache and,
when asked, the number of XLA host (CPU) devices.

Every numeric module imports ``jax`` through this module (``from fracas import _jax``), whose
import calls :func:`configure` with no argument, so that ``jax_enable_x64`` is set before any
array exists and repeated command-line runs reuse compiled executables from
``$FRACAS_CACHE_DIR`` (default ``~/.cache/fracas/jax``).

Host devices.  XLA's CPU backend exposes one device unless told otherwise; a batch
(:mod:`fracas.integrate.batch`) is split over several host devices only when the process
exposes them.  How many is the choice of the process that runs the work, not of the library:

* nothing asked (the default): fracas leaves the count alone -- XLA's default of one CPU
  device, or whatever ``--xla_force_host_platform_device_count`` the caller put in
  ``XLA_FLAGS`` itself;
* ``$FRACAS_HOST_DEVICES=N`` in the environment, or :func:`configure` ``(host_devices=N)``, or
  :func:`set_host_devices` ``(N)``: N devices (these win over a count in ``XLA_FLAGS``);
* :func:`worker_setup` ``(1)`` in each worker process of a cluster (Dask), so that N workers
  on N cores do not each claim one device per core.

The count is passed to jax as its ``jax_num_cpu_devices`` option, not through the
environment, so child processes (workers) do not inherit it.  It must be set before jax
creates its CPU backend, i.e. before the first JAX operation (``import jax`` and importing
fracas are fine).  On a jax too old to have that option the flag is written into
``XLA_FLAGS`` instead, which XLA honours only if it is set before its CPU backend starts.
"""

from __future__ import annotations

import operator
import os
import sys
from typing import SupportsIndex

__all__ = ["configure", "set_host_devices", "worker_setup", "ENV_HOST_DEVICES"]

#: Environment variable with the number of host devices for processes that do not choose.
ENV_HOST_DEVICES = "FRACAS_HOST_DEVICES"
_FLAG = "--xla_force_host_platform_device_count"

_configured = False


def _backends_initialised() -> bool:
    """Whether jax has created its backends (after which the device count is fixed)."""
    if "jax" not in sys.modules:
        return False
    from jax._src import xla_bridge

    probe = getattr(xla_bridge, "backends_are_initialized", None)
    if probe is not None:
        return bool(probe())
    return bool(getattr(xla_bridge, "_backends", {}))  # pragma: no cover - older jax


def _cpu_device_count() -> int:
    import jax

    return len(jax.devices("cpu"))


def _count(n: str | SupportsIndex, where: str) -> int:
    """``n`` (an int, a numpy integer or a decimal string) as an int >= 1, else ValueError."""
    try:
        k = int(n.strip()) if isinstance(n, str) else operator.index(n)
    except (TypeError, ValueError):
        k = 0
    if isinstance(n, bool) or k < 1:
        raise ValueError(f"{where}: the number of host devices must be an integer >= 1, got {n!r}")
    return k


def set_host_devices(n: int) -> None:
    """Make this process expose ``n`` XLA host (CPU) devices.

    Call it before jax is imported, or at least before the first JAX operation (importing
    fracas, which imports jax, is fine: jax creates its CPU backend lazily).  Once the backend
    exists the count is fixed: calling again with the count it has is a no-op, with any other
    count raises :class:`RuntimeError` (the fix is to call it earlier, or to set
    ``$FRACAS_HOST_DEVICES`` in the environment of the process).  Does not modify the
    environment (child processes do not inherit the count), except on a jax without the
    ``jax_num_cpu_devices`` option, where the count is written into ``XLA_FLAGS``.
    """
    n = _count(n, "set_host_devices")
    if _backends_initialised():
        have = _cpu_device_count()
        if have != n:
            raise RuntimeError(
                f"set_host_devices({n}): jax has already started with {have} host device(s); call "
                f"fracas._jax.set_host_devices before the first JAX operation (or set "
                f"{ENV_HOST_DEVICES}={n} in the environment of the process)"
            )
        return
    import jax

    try:
        jax.config.update("jax_num_cpu_devices", n)
    except AttributeError:  # pragma: no cover - jax without jax_num_cpu_devices
        flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(_FLAG)]
        os.environ["XLA_FLAGS"] = " ".join(flags + [f"{_FLAG}={n}"])


def configure(host_devices: int | None = None) -> None:
    """Enable float64 and the persistent compilation cache (idempotent); set the number of host
    devices when ``host_devices`` is given or ``$FRACAS_HOST_DEVICES`` is set (see
    :func:`set_host_devices`; the argument wins over the variable).  With neither the device
    count is left to XLA (one CPU device unless ``XLA_FLAGS`` says otherwise).

    Importing this module calls ``configure()``; calling it again with ``host_devices`` only
    sets the count.
    """
    global _configured
    if host_devices is not None:
        set_host_devices(host_devices)
    elif not _configured and os.environ.get(ENV_HOST_DEVICES, "").strip():
        set_host_devices(_count(os.environ[ENV_HOST_DEVICES].strip(), f"${ENV_HOST_DEVICES}"))
    if _configured:
        return
    import jax

    jax.config.update("jax_enable_x64", True)
    cache_dir = os.environ.get("FRACAS_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "fracas", "jax"))
    if cache_dir.lower() not in ("", "0", "off", "none"):
        try:
            os.makedirs(cache_dir, exist_ok=True)
            jax.config.update("jax_compilation_cache_dir", cache_dir)
            jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
        except OSError:  # read-only home: run without the cache
            pass
    _configured = True


def worker_setup(n: int = 1) -> None:
    """Set up JAX in a worker process of a cluster: float64, the compilation cache and ``n``
    host devices (default one: a cluster gets its parallelism from its workers, and N workers
    on N cores must not each claim one device per core).

    Call it in the worker before its first task touches JAX, e.g. from a Dask worker plugin::

        class FracasWorker(distributed.WorkerPlugin):
            def setup(self, worker):
                from fracas._jax import worker_setup
                worker_setup(1)

        client.register_plugin(FracasWorker())      # or: client.run(worker_setup, 1)

    Raises :class:`RuntimeError` if the worker's jax has already started with another count.
    """
    configure(host_devices=n)


configure()
