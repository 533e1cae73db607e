"""Many propagations in one compiled call: ``jax.vmap`` over initial states (and parameters),
chunked to bound memory and sharded over every host device (dispersions, Monte Carlo, grids).

    tr = propagate_batch(model, params, ephem, epoch_et_s, x0s, t_out)          # x0s (N, 7)
    tr, sens = propagate_batch(..., with_sensitivities=True, param_labels=("mu[sun]",))

The N initial states are cut into chunks of ``chunk_size`` rows (fewer when N is smaller:
then one chunk of N rows, rounded up to a multiple of the device count); the last chunk is
padded with copies of its last row, so every chunk has the same shape and the batched
program is traced and compiled once per (chunk shape, model, options).  Each chunk runs as
one ``vmap`` of :func:`fracas.integrate.propagate.propagate` (or of
``propagate_with_sensitivities``): a single ``while_loop`` whose lanes advance together until
the slowest lane is done, so the cost of a chunk is (largest step count in the chunk) x (chunk
size); group similar propagations into the same batch.

Parallelism.  XLA's CPU backend advances one while loop on one device; it may overlap
independent operations of the loop body on other threads, but that does not scale with the
batch.  To use several cores, the process must expose several *host devices*, which it
chooses before its first JAX operation: ``fracas._jax.set_host_devices(N)``,
``$FRACAS_HOST_DEVICES=N`` or ``--xla_force_host_platform_device_count=N`` in ``XLA_FLAGS``
(by default a process has one; see :func:`host_devices`).  With more than one device each chunk is split over them with
``jax.shard_map``: every device runs its own while loop on its slice of the chunk, with no
communication between devices (a plain ``NamedSharding`` of a vmapped while loop would
all-reduce the loop condition at every iteration and keep the devices in lock step).

Batched parameters.  ``params_axes`` says which ``Params`` leaves carry the batch on their
axis 0 (one value per propagation), like ``in_axes`` of ``jax.vmap``: ``None`` (all shared,
the default), ``0`` (every leaf batched), a dict ``{field: 0}`` or a ``Params`` whose fields are
``0`` or ``None``.

Outputs are numpy arrays (host memory, one chunk resident on the device at a time) with the
batch as their leading axis: a :class:`~fracas.integrate.propagate.Trajectory` (and a
:class:`~fracas.integrate.propagate.Sensitivities`) whose every field has shape (N, ...).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from fracas import _jax  # noqa: F401  (float64, compilation cache)
from fracas.dynamics.model import ForceModel, Params
from fracas.integrate.propagate import Sensitivities, Trajectory, propagate, propagate_with_sensitivities

if TYPE_CHECKING:
    from jax.typing import ArrayLike

    from fracas.dynamics.ephemeris import EphemerisTable

try:  # integrator constants as traced values: one executable for every c_nom, dt_max ...
    from fracas.integrate.propagate import join_model, split_model
except ImportError:  # pragma: no cover - older core: the whole model is static
    join_model = split_model = None

_AXIS = "batch"


def host_devices(backend: str | None = None) -> list:
    """The devices a batch is split over: ``jax.devices(backend)`` (default backend).

    On CPU this is the number of host devices the process chose before jax created its CPU
    backend (default 1): :func:`fracas._jax.set_host_devices`, ``$FRACAS_HOST_DEVICES``, or
    ``--xla_force_host_platform_device_count`` in ``XLA_FLAGS`` before ``import jax``.  The
    library never picks one device per core by itself (a cluster worker keeps one, see
    :func:`fracas._jax.worker_setup`).  XLA's CPU runtime may run independent operations of
    one program concurrently, but a vmapped ``while_loop`` advances on one device: sharding
    gave 1.5x on 2 (shared) cores in ``benchmarks/results_cpu.txt``.

    Several host devices do not slow single propagations (they run on device 0).  On a GPU
    backend this returns the GPUs.
    """
    return list(jax.devices(backend))


def _normalise_axes(params_axes) -> tuple:
    """Per-field axis (0 or None) of ``Params``, as a hashable tuple."""
    fields = Params._fields
    if params_axes is None:
        axes = (None,) * len(fields)
    elif isinstance(params_axes, int):
        axes = (params_axes,) * len(fields)
    elif isinstance(params_axes, Params):
        axes = tuple(params_axes)
    elif isinstance(params_axes, dict):
        unknown = set(params_axes) - set(fields)
        if unknown:
            raise KeyError(f"unknown Params fields in params_axes: {sorted(unknown)}")
        axes = tuple(params_axes.get(f) for f in fields)
    else:
        raise TypeError("params_axes: None, 0, a dict {field: 0} or a Params of 0/None")
    for f, a in zip(fields, axes):
        if a not in (None, 0):
            raise ValueError(f"params_axes[{f!r}] = {a!r}: only 0 (batched on axis 0) or None")
    return axes


def _split(model: ForceModel):
    """(static model, traced integrator constants) when the core supports it, else (model, ())."""
    if split_model is None:
        return model, ()
    return split_model(model)


@functools.lru_cache(maxsize=64)
def _batched_fn(static: ForceModel, with_sens: bool, labels: tuple, axes: tuple, devices: tuple, sens_method="auto"):
    """The jitted, vmapped (and, over several devices, shard_mapped) propagation of one chunk.

    ``static`` is the model without its integrator constants, which arrive as the traced
    argument ``dyn``: changing c_nom or dt_max reuses the executable.
    """
    in_axes_p = Params(*axes)

    def model_of(dyn):
        return static if split_model is None else join_model(static, dyn)

    if with_sens:

        def one(dyn, params, ephem, epoch, x0, t_out):
            return propagate_with_sensitivities(model_of(dyn), params, ephem, epoch, x0, t_out, labels, sens_method)

    else:

        def one(dyn, params, ephem, epoch, x0, t_out):
            return propagate(model_of(dyn), params, ephem, epoch, x0, t_out)

    vm = jax.vmap(one, in_axes=(None, in_axes_p, None, None, 0, None))
    if len(devices) == 1:
        return jax.jit(vm)  # placed on devices[0] by the caller's device_put
    mesh = Mesh(np.array(devices), (_AXIS,))
    p_spec = Params(*[P(_AXIS) if a == 0 else P() for a in axes])
    sm = _shard_map(vm, mesh, in_specs=(P(), p_spec, P(), P(), P(_AXIS), P()), out_specs=P(_AXIS))
    return jax.jit(sm)


def _shard_map(f, mesh, in_specs, out_specs):
    """``jax.shard_map`` (new API) or ``jax.experimental.shard_map.shard_map`` (older jax)."""
    if hasattr(jax, "shard_map"):
        try:
            return jax.shard_map(f, mesh=mesh, in_specs=in_specs, out_specs=out_specs, check_vma=False)
        except TypeError:  # pragma: no cover - jax without check_vma
            return jax.shard_map(f, mesh=mesh, in_specs=in_specs, out_specs=out_specs)
    from jax.experimental.shard_map import shard_map  # pragma: no cover

    return shard_map(f, mesh=mesh, in_specs=in_specs, out_specs=out_specs, check_rep=False)


def _pad_rows(a: np.ndarray, start: int, stop: int, size: int) -> np.ndarray:
    """Rows start:stop of ``a``, padded to ``size`` rows with copies of the last row."""
    part = a[start:stop]
    if part.shape[0] < size:
        pad = np.repeat(part[-1:], size - part.shape[0], axis=0)
        part = np.concatenate([part, pad], axis=0)
    return part


#: Default lanes per device and chunk (benchmarks/results_highorder.txt, "chunk size"): a
#: DPRKN12 LEO chunk's working set stays in the 2 MB L2 of this machine's cores up to ~1000
#: lanes of state, ~250 with a 7x7 STM; larger chunks fell out of it and ran slower, smaller
#: ones paid per-call dispatch.
CHUNK_PER_DEVICE = 1024
CHUNK_PER_DEVICE_SENS = 256


def auto_chunk_size(n_devices: int, with_sensitivities: bool) -> int:
    """Lanes per chunk for this machine: per-device lanes x devices (see CHUNK_PER_DEVICE)."""
    per = CHUNK_PER_DEVICE_SENS if with_sensitivities else CHUNK_PER_DEVICE
    return per * max(1, int(n_devices))


def chunk_rows(n: int, chunk_size: int, n_devices: int) -> int:
    """Rows per chunk: ``chunk_size``, or for a smaller batch the next power of two >= n (so
    batches of many sizes share a few compiled programs), as a multiple of ``n_devices``."""
    n = max(1, int(n))
    chunk_size = max(1, int(chunk_size))
    rows = chunk_size if n >= chunk_size else min(chunk_size, 1 << (n - 1).bit_length())
    return -(-rows // n_devices) * n_devices


def step_count_proxy(x0s: np.ndarray, mu: float, span_s: float) -> np.ndarray:
    """A cheap estimate of how many steps each lane needs, to group similar lanes in a chunk.

    Revolutions over the span times a factor for eccentricity ((1 + e)/(1 - e))^(3/4) (the
    ratio of the apoapsis and periapsis time scales, to the power at which the step count of
    a high-order method grows); for unbound states the span over the time scale r^1.5/sqrt(mu).
    """
    r = x0s[:, :3]
    v = x0s[:, 3:6]
    rn = np.linalg.norm(r, axis=1)
    energy = 0.5 * np.einsum("ij,ij->i", v, v) - mu / rn
    h = np.cross(r, v)
    e = np.sqrt(np.maximum(0.0, 1.0 + 2.0 * energy * np.einsum("ij,ij->i", h, h) / mu**2))
    bound = (energy < 0) & (e < 1)
    a = np.where(bound, -mu / (2.0 * np.where(energy < 0, energy, -1.0)), rn)
    period = 2.0 * np.pi * np.sqrt(a**3 / mu)
    ecc = np.where(bound, ((1.0 + e) / np.maximum(1.0 - e, 1e-6)) ** 0.75, 1.0)
    return abs(span_s) / period * ecc


def propagate_batch(
    model: ForceModel,
    params: Params,
    ephem: EphemerisTable | None,
    epoch_et_s: ArrayLike,
    x0s: ArrayLike,
    t_out: ArrayLike,
    chunk_size: int | None = None,
    with_sensitivities: bool = False,
    param_labels: Sequence[str] = (),
    params_axes: None | int | dict | Params = None,
    devices: Sequence | None = None,
    progress: Callable[[int, int], None] | None = None,
    group_lanes: bool | None = None,
    sensitivity_method: str = "auto",
    stage_loop: str | None = "unrolled",
) -> Trajectory | tuple[Trajectory, Sensitivities]:
    """Propagate every row of ``x0s`` (N, 7) through ``t_out`` (shared output times).

    Same conventions and outputs as :func:`~fracas.integrate.propagate.propagate` (and, with
    ``with_sensitivities``, :func:`~fracas.integrate.propagate.propagate_with_sensitivities`
    with ``param_labels``; no labels gives the 7x7 STMs only), with a leading batch axis of
    length N on every output field (numpy arrays).  ``params_axes`` batches ``Params`` leaves
    (see the module docstring); ``devices`` overrides :func:`host_devices` (e.g. one device
    to compare against a sharded run).  ``progress(done, total)`` is called after every chunk
    (the command line and Monte Carlo drivers hang a progress bar on it).  Returns a
    ``Trajectory``, or ``(Trajectory, Sensitivities)`` when ``with_sensitivities``.

    ``chunk_size``: lanes per compiled call (None: :func:`auto_chunk_size` for the devices).
    ``group_lanes``: sort the lanes by :func:`step_count_proxy` before chunking (results come
    back in the caller's order), so that lanes needing many steps share chunks and the others
    do not idle behind them (a vmapped loop runs every lane until its chunk's slowest is done;
    1.95x on a 50/50 mix of LEO and 12 h orbits, benchmarks/results_highorder.txt).  None
    (default): grouped when the batch spans more than one chunk (it cannot matter otherwise).
    ``sensitivity_method``: "auto" | "ad" | "variational" (see ``propagate_with_sensitivities``).
    ``stage_loop``: how the compiled step runs its stages (``IntegratorSettings.stage_loop``);
    "unrolled" by default: on XLA CPU a wide vmapped batch runs ~15x faster with one fused
    copy of the force model per stage than with the stages under a loop (LEO + J2 DPRKN12,
    1000 lanes: 15.2k vs 0.97k propagations per CPU-second; benchmarks/bench_heyoka_ratio.py),
    at the price of a larger program (compiled once per force-model shape).  None keeps the
    model's own setting.  Not a rule for every vmapped caller: TSIM's mission programs
    (vmapped propagations in 32-cell chunks, thrust arcs) measured faster with the loop
    (earth_mars_tsim.toml warm 19 s vs 26 s unrolled; cold 28 s vs 42 s) and keep it.
    """
    x0s, params, axes, devs = _batch_inputs(x0s, params, params_axes, devices)
    n = x0s.shape[0]
    if chunk_size is None:
        chunk_size = auto_chunk_size(len(devs), with_sensitivities)
    rows = chunk_rows(n, chunk_size, len(devs))
    if group_lanes is None:
        group_lanes = n > rows
    order = None
    if group_lanes and n > 1:
        order = _grouping_order(model, params, axes, x0s, t_out)
        x0s = x0s[order]
        params = Params(*[v[order] if a == 0 else v for v, a in zip(params, axes)])
    if stage_loop not in (None, "loop", "unrolled"):
        raise ValueError(f"stage_loop = {stage_loop!r}: expected 'loop', 'unrolled' or None")
    static, dyn = _split(model)
    if stage_loop is not None and static.integrator.stage_loop != stage_loop:
        static = dataclasses.replace(static, integrator=dataclasses.replace(static.integrator, stage_loop=stage_loop))
    fn = _batched_fn(static, bool(with_sensitivities), tuple(param_labels), axes, devs, sensitivity_method)
    t_out = jnp.asarray(t_out, jnp.float64)
    epoch = jnp.asarray(epoch_et_s, jnp.float64)
    single = devs[0] if len(devs) == 1 else None
    out = _run_chunks(fn, (dyn, ephem, epoch, t_out), x0s, params, axes, rows, single, progress)
    if order is not None:
        inverse = np.empty_like(order)
        inverse[order] = np.arange(n)
        out = jax.tree_util.tree_map(lambda a: a[inverse], out)
    return out


def _batch_inputs(x0s: ArrayLike, params: Params, params_axes: object, devices: Sequence | None) -> tuple:
    """(x0s, params, axes, devices) of :func:`propagate_batch`, checked: x0s (N, 7) float64,
    the batched ``Params`` leaves as float64 arrays with N rows, the device tuple."""
    x0s = np.asarray(x0s, dtype=np.float64)
    if x0s.ndim != 2 or x0s.shape[1] != 7:
        raise ValueError(f"x0s must have shape (N, 7), got {x0s.shape}")
    n = x0s.shape[0]
    if n == 0:
        raise ValueError("x0s is empty")
    axes = _normalise_axes(params_axes)
    devs = tuple(devices) if devices is not None else tuple(host_devices())
    if not devs:
        raise ValueError("no devices")
    params = Params(*[np.asarray(v, np.float64) if a == 0 else v for v, a in zip(params, axes)])
    for f, v, a in zip(Params._fields, params, axes):
        if a == 0 and (v.ndim == 0 or v.shape[0] != n):
            raise ValueError(f"params.{f} is batched (params_axes) but its axis 0 is not N = {n}")
    return x0s, params, axes, devs


def _grouping_order(model: ForceModel, params: Params, axes: tuple, x0s: np.ndarray, t_out: ArrayLike) -> np.ndarray:
    """Lane order by :func:`step_count_proxy` (stable), for ``group_lanes``."""
    t_arr = np.asarray(t_out, np.float64)
    mu_p = (
        float(np.asarray(params.mu)[model.primary]) if axes[0] is None else float(np.mean(params.mu[:, model.primary]))
    )
    return np.argsort(step_count_proxy(x0s, mu_p, float(t_arr[-1] - t_arr[0])), kind="stable")


def _run_chunks(
    fn: Callable,
    shared: tuple,
    x0s: np.ndarray,
    params: Params,
    axes: tuple,
    rows: int,
    single: object | None,
    progress: Callable[[int, int], None] | None,
) -> object:
    """Every chunk of ``rows`` lanes through ``fn`` (``shared`` = (dyn, ephem, epoch, t_out)),
    the outputs concatenated on the host in lane order."""
    dyn, ephem, epoch, t_out = shared
    n = x0s.shape[0]

    def launch(start: int) -> tuple:
        stop = min(start + rows, n)
        xs = _pad_rows(x0s, start, stop, rows)
        ps = Params(*[_pad_rows(v, start, stop, rows) if a == 0 else v for v, a in zip(params, axes)])
        args = (dyn, ps, ephem, epoch, xs, t_out)
        if single is not None:
            args = jax.device_put(args, single)
        return stop - start, fn(*args)

    # double buffering: chunk k+1 is dispatched before chunk k is copied to the host
    pieces = []
    done = 0

    def collect(pending: tuple) -> None:
        nonlocal done
        pieces.append(_to_host(*pending))
        done += pending[0]
        if progress is not None:
            progress(done, n)

    pending = launch(0)
    for start in range(rows, n, rows):
        nxt = launch(start)
        collect(pending)
        pending = nxt
    collect(pending)
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=0), *pieces)


def _to_host(n_valid: int, out: object) -> object:
    return jax.tree_util.tree_map(lambda a: np.asarray(a)[:n_valid], out)


__all__ = [
    "propagate_batch",
    "host_devices",
    "chunk_rows",
    "auto_chunk_size",
    "step_count_proxy",
    "Trajectory",
    "Sensitivities",
]
