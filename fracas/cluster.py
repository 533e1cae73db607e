"""Dask for fracas's parallel runners: sweeps (:mod:`fracas.modes.sweep.run`) and TSIM Monte Carlo
batches (:mod:`fracas.modes.tsim.run`).  Every call to ``distributed`` is in this module.

* :func:`start` starts a Dask LocalCluster of single-threaded worker processes, or connects
  to a running scheduler at an address, registers the worker plugin (:func:`worker_plugin`:
  float64, the compilation cache and one XLA host device per worker,
  :func:`fracas._jax.worker_setup`) and returns a :class:`Pool`; :func:`open_pool` gives, for
  ``workers=0`` and no scheduler, a Pool that runs every task in this process (no Dask).
* A Pool runs calls ``(function, args)``: it yields each one's :class:`Done` (its index in
  the list of calls, its result or its error) in the calls' order (:meth:`Pool.ordered`) or
  as they complete (:meth:`Pool.as_completed`, :meth:`Pool.completed_batches`), calling
  ``progress(done, total)`` (tasks) after each; :meth:`Pool.share` sends a large argument
  to every worker once.  Closing it (``with`` or :meth:`Pool.close`) closes the client and
  the LocalCluster it started.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from fracas.errors import FracasError

__all__ = [
    "Call",
    "Done",
    "Pool",
    "SINGLE_THREAD_ENV",
    "open_pool",
    "start",
    "start_cluster",
    "worker_plugin",
]

#: a task: a function and its positional arguments
Call = tuple[Callable[..., Any], tuple[Any, ...]]
Progress = Callable[[int, int], None]

# One core per worker process: XLA's CPU thread pool and the BLAS libraries would otherwise
# each take every core, and N workers on N cores would oversubscribe them.
SINGLE_THREAD_ENV = {
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


@dataclass(frozen=True)
class Done:
    """A finished task: ``index`` (its place in the list of calls), its ``result``, or the
    ``error`` it raised (a lost worker, a pickling error, the function's own exception)."""

    index: int
    result: Any = None
    error: BaseException | None = None

    def value(self) -> Any:
        """The task's result; its error raised again."""
        if self.error is not None:
            raise self.error
        return self.result


# ----------------------------------------------------------------------------- workers
class _WorkerSetup:
    """Dask worker plugin: one XLA host device per worker, before any task touches JAX."""

    name = "fracas-worker-setup"

    def setup(self, worker: Any = None) -> None:
        from fracas._jax import worker_setup

        worker_setup(1)
        _ignore_interrupts()


def _quiet_logs() -> None:
    """Dask's and Tornado's loggers off in this process (a worker about to be closed)."""
    import logging

    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _ignore_interrupts() -> None:
    """A worker process ignores SIGINT: Ctrl-C reaches every process of the terminal's group,
    and the command (which closes the cluster) says "interrupted" once; a worker interrupted
    on its own would log pages of warnings and tracebacks as its tasks are cancelled."""
    import signal

    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the worker process's main thread: leave it
        pass


@contextlib.contextmanager
def _spawning_ignores_interrupts() -> Iterator[None]:
    """SIGINT ignored while the LocalCluster spawns its worker processes: an ignored signal
    stays ignored across exec (POSIX) and Python then installs no KeyboardInterrupt handler,
    so a Ctrl-C that reaches the terminal's process group while a worker is still importing
    Dask (before :func:`_ignore_interrupts` runs in it) prints no traceback there.  The
    command's own handler is restored at once after; a Ctrl-C in that start-up window (a few
    seconds) is dropped, and the next one interrupts the run as usual."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def worker_plugin() -> Any:
    """The Dask worker plugin every fracas cluster registers (:class:`_WorkerSetup`)."""
    from distributed import WorkerPlugin

    class FracasWorker(_WorkerSetup, WorkerPlugin):
        pass

    return FracasWorker()


def start_cluster(
    workers: int | None,
    n_tasks: int,
    scheduler: str | None,
    env: dict[str, str] | None = None,
    timeout: str | None = None,
) -> tuple[Any, Any]:
    """(LocalCluster or None, Client): a LocalCluster of single-threaded worker processes
    (``workers``, default one per core, at most ``n_tasks``; ``env`` set in each worker
    process), or a client of the running scheduler at ``scheduler``."""
    from distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        n = workers if workers is not None else (os.cpu_count() or 1)
        extra = {"env": env} if env else {}
        with _spawning_ignores_interrupts():
            cluster = LocalCluster(
                n_workers=max(1, min(n, n_tasks)),
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                **extra,
            )
    try:
        client = Client(cluster if cluster is not None else scheduler, **({"timeout": timeout} if timeout else {}))
    except Exception:
        if cluster is not None:
            cluster.close()
        raise
    return cluster, client


# ----------------------------------------------------------------------------- running tasks
class Pool:
    """Where tasks run: a Dask client (and the LocalCluster started for it, if any), or this
    process (``client`` None: each task called in turn, in the calls' order)."""

    def __init__(self, client: Any = None, cluster: Any = None, n_workers: int = 1) -> None:
        self.client, self.cluster, self.n_workers = client, cluster, n_workers

    @property
    def in_process(self) -> bool:
        """Whether the tasks run in this process (no Dask)."""
        return self.client is None

    def share(self, value: Any) -> Any:
        """``value`` as a task argument sent to every worker once (Dask ``scatter``); in this
        process, ``value`` itself."""
        return value if self.in_process else self.client.scatter(value, broadcast=True)

    def completed_batches(
        self, calls: Iterable[Call], *, catch: bool = True, progress: Progress | None = None
    ) -> Iterator[list[Done]]:
        """Run every call; yield the tasks that finished together (in this process: one at a
        time, in order), each as its :class:`Done`.  ``catch``: a task's exception comes back
        as its Done's ``error``; else it is raised here.  ``progress(done, total)`` after each."""
        calls = list(calls)
        count = 0
        for batch in self._batches(calls, catch):
            for _ in batch:
                count += 1
                if progress is not None:
                    progress(count, len(calls))
            yield batch

    def as_completed(
        self, calls: Iterable[Call], *, catch: bool = True, progress: Progress | None = None
    ) -> Iterator[Done]:
        """:meth:`completed_batches`, one task at a time (the order they finish in)."""
        for batch in self.completed_batches(calls, catch=catch, progress=progress):
            yield from batch

    def ordered(self, calls: Iterable[Call], *, catch: bool = True, progress: Progress | None = None) -> Iterator[Done]:
        """Run every call (all submitted at once on a cluster); yield their :class:`Done` in
        the calls' order.  ``catch`` and ``progress`` as in :meth:`completed_batches`."""
        calls = list(calls)
        if self.in_process:
            done: Iterable[Done] = (_called(i, fn, args, catch) for i, (fn, args) in enumerate(calls))
        else:
            futures = self._submit(calls)
            done = (_result(i, fut, catch) for i, fut in enumerate(futures))
        for count, d in enumerate(done, start=1):
            if progress is not None:
                progress(count, len(calls))
            yield d

    def _submit(self, calls: list[Call]) -> list[Any]:
        return [self.client.submit(fn, *args, pure=False) for fn, args in calls]

    def _batches(self, calls: list[Call], catch: bool) -> Iterator[list[Done]]:
        if self.in_process:
            for i, (fn, args) in enumerate(calls):
                yield [_called(i, fn, args, catch)]
            return
        from distributed import as_completed

        futures = self._submit(calls)
        index = {fut: i for i, fut in enumerate(futures)}
        for batch in as_completed(futures).batches():  # results that arrive together
            yield [_result(index[fut], fut, catch) for fut in batch]

    def close(self) -> None:
        """Close the client, then the LocalCluster started for it (if any)."""
        try:
            if self.client is not None:
                self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if isinstance(exc_type, type) and issubclass(exc_type, KeyboardInterrupt):
            self._quiet_workers()
        self.close()

    def _quiet_workers(self) -> None:
        """Interrupted: every worker's Dask logging off before the cluster closes under its
        running tasks (cancelled tasks and lost heartbeats would each log a warning)."""
        if self.client is None:
            return
        try:
            self.client.run(_quiet_logs, wait=True)
        except Exception:  # noqa: BLE001 - a worker already gone: nothing to quiet
            pass


def _done(index: int, result: Callable[[], Any], catch: bool) -> Done:
    """Task ``index``'s :class:`Done` of ``result()``; with ``catch``, the exception it raises
    is the Done's error instead of passing on."""
    if not catch:
        return Done(index, result())
    try:
        return Done(index, result())
    except Exception as exc:  # noqa: BLE001 - a lost worker, a pickling error, the task's failure
        return Done(index, error=exc)


def _called(index: int, fn: Callable[..., Any], args: tuple[Any, ...], catch: bool) -> Done:
    """A task run in this process."""
    return _done(index, lambda: fn(*args), catch)


def _result(index: int, fut: Any, catch: bool) -> Done:
    """A task run on a Dask worker (its future)."""
    return _done(index, fut.result, catch)


def start(
    workers: int | None,
    n_tasks: int,
    scheduler: str | None,
    *,
    env: dict[str, str] | None = None,
    timeout: str | None = None,
    one_line: bool = False,
) -> Pool:
    """A :class:`Pool` on a new LocalCluster (``workers`` processes, default one per core,
    at most ``n_tasks``; ``env`` set in each) or on the running scheduler at ``scheduler``,
    with the worker plugin registered.  ``one_line``: a cluster that cannot start (an address
    that does not answer, a worker that cannot start) is a one-line FracasError naming it."""
    try:
        cluster, client = start_cluster(workers, n_tasks, scheduler, env=env, timeout=timeout)
    except Exception as exc:  # noqa: BLE001
        if not one_line:
            raise
        where = f"the Dask scheduler at {scheduler}" if scheduler else "a Dask LocalCluster"
        raise FracasError(f"could not start {where}: {type(exc).__name__}: {exc}") from None
    pool = Pool(client, cluster)
    try:
        client.register_plugin(worker_plugin())
        pool.n_workers = len(client.scheduler_info().get("workers", {})) or 1
    except BaseException:
        pool.close()
        raise
    return pool


def open_pool(
    workers: int | None,
    n_tasks: int,
    scheduler: str | None,
    *,
    env: dict[str, str] | None = None,
    timeout: str | None = None,
    one_line: bool = False,
) -> Pool:
    """This process's :class:`Pool` for ``workers=0`` and no scheduler, else :func:`start`."""
    if workers == 0 and scheduler is None:
        return Pool()
    return start(workers, n_tasks, scheduler, env=env, timeout=timeout, one_line=one_line)
