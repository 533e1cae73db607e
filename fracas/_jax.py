"""One place that configures JAX: float64 everywhere and the persistent compilation cache.

Every numeric module imports ``jax`` through :func:`jax_module` (or calls :func:`configure`
first), so that ``jax_enable_x64`` is set before any array exists and repeated command-line
runs reuse compiled executables from ``$FRACAS_CACHE_DIR`` (default ``~/.cache/fracas/jax``).
"""

from __future__ import annotations

import os

_configured = False


def _host_device_flag() -> None:
    """Expose one XLA host device per CPU core (``$FRACAS_HOST_DEVICES`` overrides), so that
    batches can be sharded over cores (XLA runs one vmapped while loop on one thread).  Must
    happen before jax is first imported; has no effect afterwards and never overrides a
    count already in ``XLA_FLAGS``.  Single propagations run on device 0 either way."""
    import sys

    if "jax" in sys.modules:
        return
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_force_host_platform_device_count" in flags:
        return
    n = os.environ.get("FRACAS_HOST_DEVICES") or str(os.cpu_count() or 1)
    os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={int(n)}".strip()


def configure() -> None:
    """Enable float64 and the persistent compilation cache (idempotent)."""
    global _configured
    if _configured:
        return
    _host_device_flag()
    import jax

    jax.config.update("jax_enable_x64", True)
    cache_dir = os.environ.get(
        "FRACAS_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "fracas", "jax")
    )
    if cache_dir.lower() not in ("", "0", "off", "none"):
        try:
            os.makedirs(cache_dir, exist_ok=True)
            jax.config.update("jax_compilation_cache_dir", cache_dir)
            jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
        except OSError:  # read-only home: run without the cache
            pass
    _configured = True


configure()
