"""The Dask runner (fracas.cluster): results in the calls' order or as they complete, each
with its index; a failing task reported with its index (or raised); in this process for no
workers; a LocalCluster of one worker process with the worker plugin; closing it."""

from __future__ import annotations

import operator
import time

import pytest

from fracas import cluster

CALLS = [(operator.mul, (i, 10)) for i in range(5)]


def test_in_process_pool_for_no_workers():
    """workers=0 and no scheduler: no Dask; each task called in turn, in order; share()
    gives the value itself; one worker."""
    pool = cluster.open_pool(0, 5, None)
    assert pool.in_process and pool.n_workers == 1 and pool.client is None
    marker = object()
    assert pool.share(marker) is marker
    seen = []
    with pool:
        done = list(pool.ordered(CALLS, progress=lambda d, t: seen.append((d, t))))
    assert [d.index for d in done] == [0, 1, 2, 3, 4]
    assert [d.value() for d in done] == [0, 10, 20, 30, 40]
    assert seen == [(1, 5), (2, 5), (3, 5), (4, 5), (5, 5)]


def test_in_process_as_completed_and_batches_keep_the_order():
    """In this process the tasks complete in the calls' order, one per batch."""
    pool = cluster.Pool()
    got = [(d.index, d.result) for d in pool.as_completed(CALLS)]
    assert got == [(i, 10 * i) for i in range(5)]
    batches = list(pool.completed_batches(CALLS))
    assert [[d.index for d in b] for b in batches] == [[0], [1], [2], [3], [4]]


def test_a_failing_task_is_reported_with_its_index():
    """catch=True (the default): the failing task's Done carries its index and error, the
    others their results; value() raises it again.  catch=False: raised where it happens."""
    calls = [(operator.truediv, (1.0, 2.0)), (operator.truediv, (1.0, 0.0)), (operator.truediv, (3.0, 1.0))]
    pool = cluster.Pool()
    done = list(pool.ordered(calls))
    assert [d.index for d in done] == [0, 1, 2]
    assert done[0].value() == 0.5 and done[2].value() == 3.0
    assert done[1].result is None and isinstance(done[1].error, ZeroDivisionError)
    with pytest.raises(ZeroDivisionError):
        done[1].value()
    it = pool.as_completed(calls, catch=False)
    assert next(it).result == 0.5
    with pytest.raises(ZeroDivisionError):
        next(it)


def test_unreachable_scheduler_is_one_line():
    """one_line: a scheduler that does not answer is a one-line FracasError naming it;
    without it, the client's own error."""
    from fracas.errors import FracasError

    with pytest.raises(FracasError, match=r"^could not start the Dask scheduler at tcp://127.0.0.1:9: "):
        cluster.start(None, 1, "tcp://127.0.0.1:9", timeout="1s", one_line=True)
    with pytest.raises(Exception) as exc:
        cluster.start(None, 1, "tcp://127.0.0.1:9", timeout="1s")
    assert not isinstance(exc.value, FracasError)


@pytest.fixture(scope="module")
def one_worker():
    """A LocalCluster of one single-threaded worker process (the worker plugin registered)."""
    t0 = time.perf_counter()
    pool = cluster.start(1, 5, None, env=cluster.SINGLE_THREAD_ENV, timeout="60s")
    print(f"\nLocalCluster of 1 worker started in {time.perf_counter() - t0:.1f} s")
    yield pool
    pool.close()


def test_local_cluster_of_one_worker(one_worker):
    """Ordered results, results as completed (each with its index), a shared argument, a
    failing task with its index, the worker plugin set up on the worker."""
    pool = one_worker
    assert not pool.in_process and pool.n_workers == 1
    assert [d.value() for d in pool.ordered(CALLS)] == [0, 10, 20, 30, 40]
    got = sorted((d.index, d.result) for d in pool.as_completed(CALLS))
    assert got == [(i, 10 * i) for i in range(5)]
    shared = pool.share(7)
    assert [d.value() for d in pool.ordered([(operator.add, (shared, i)) for i in range(3)])] == [7, 8, 9]
    calls = [(operator.truediv, (1.0, 2.0)), (operator.truediv, (1.0, 0.0))]
    seen = []
    done = {d.index: d for b in pool.completed_batches(calls, progress=lambda *a: seen.append(a)) for d in b}
    assert done[0].value() == 0.5 and isinstance(done[1].error, ZeroDivisionError)
    assert seen == [(1, 2), (2, 2)]
    plugins = pool.client.run(lambda dask_worker: sorted(dask_worker.plugins))
    assert all("fracas-worker-setup" in names for names in plugins.values())


def test_closing_a_pool_closes_its_cluster():
    """close() closes the client and the LocalCluster started for it."""
    pool = cluster.start(1, 1, None, timeout="60s")
    local = pool.cluster
    with pool:
        assert pool.ordered([(operator.neg, (3,))]).__next__().value() == -3
    assert local.status.name == "closed"
    assert pool.client.status == "closed"
