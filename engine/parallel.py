"""Where the per-block and per-chunk work of a build runs: this process, a local process pool, or a Dask cluster.

Every caller hands its work to a :class:`concurrent.futures.Executor` and reads the results in submission
order, so a build is the same code whichever executor runs it (issue 12 item 3). A Dask cluster is reached
through ``distributed.Client.get_executor()``, which is such an executor too.
"""

from __future__ import annotations

import os
import pickle
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import contextmanager
from functools import partial
from typing import Any, ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController, threadpool_limits

from engine.errors import InvalidParameter
from engine.heap import keep_big_buffers_out_of_the_heap
from engine.payloads import FileUnreachable

P = ParamSpec("P")
R = TypeVar("R")

#: Seconds to wait for a Dask scheduler to answer before the build gives up with a clear error.
CONNECT_TIMEOUT_S = 20


def run_single_threaded(fn: Callable[..., R], *args: Any, **kwargs: Any) -> R:
    """Call ``fn`` with one BLAS thread: a worker's small banded solves only spin on more, and fight the
    other workers for the cores."""
    keep_big_buffers_out_of_the_heap()  # once per process
    with thread_pools().limit(limits=1):
        return fn(*args, **kwargs)


#: This process's thread pools and the number of modules imported when they were found (see :func:`thread_pools`).
_pools: tuple[int, ThreadpoolController] | None = None


def thread_pools() -> ThreadpoolController:
    """The BLAS and OpenMP thread pools this process has loaded, found again only when a module has been imported
    since (a new one may bring a library). Finding them walks every loaded library: once per task, as
    ``threadpool_limits`` does, it was 3 % of a Dask worker's time on the 16x terrain."""
    global _pools
    if _pools is None or _pools[0] != len(sys.modules):
        _pools = (len(sys.modules), ThreadpoolController())
    return _pools[1]


class SingleThreadedExecutor(Executor):
    """An executor that runs each task of another one with one BLAS thread (see :func:`run_single_threaded`)."""

    def __init__(self, inner: Executor) -> None:
        self.inner = inner

    def submit(self, fn: Callable[P, R], /, *args: P.args, **kwargs: P.kwargs) -> Future[R]:  # noqa: D102
        return self.inner.submit(partial(run_single_threaded, fn, *args, **kwargs))

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:  # noqa: D102
        self.inner.shutdown(wait=wait, cancel_futures=cancel_futures)


def run_pickled(task: bytes) -> Any:
    """Run a task :class:`PickledTaskExecutor` sent: ``fn(*args, **kwargs)`` from their pickle."""
    fn, args, kwargs = pickle.loads(task)
    return fn(*args, **kwargs)


class PickledTaskExecutor(SingleThreadedExecutor):
    """A :class:`SingleThreadedExecutor` that sends each task as one pickle (bytes) of its function and
    arguments, as a process pool does.

    A Dask task's arguments go through the scheduler, which unpickles and pickles again whatever objects they
    hold (every contour's arrays, one by one); a bytes object passes through it as it is. The scheduler shares
    the machine with the workers on a small cluster, and that was seconds of its CPU per build.
    """

    def submit(self, fn: Callable[P, R], /, *args: P.args, **kwargs: P.kwargs) -> Future[R]:  # noqa: D102
        task = pickle.dumps((partial(run_single_threaded, fn), args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
        return self.inner.submit(run_pickled, task)


def _set_up_worker() -> None:
    threadpool_limits(1)
    keep_big_buffers_out_of_the_heap()


def local_pool(workers: int) -> Executor:
    """A process pool of ``workers`` processes, each with one BLAS thread."""
    _start_numba_here()
    return ProcessPoolExecutor(max_workers=workers, initializer=_set_up_worker)


def _start_numba_here() -> None:
    """Start numba's compiler in this process (its first kernel would anyway): the pool's workers are forked from
    it and inherit it, where each had spent a sixth of a second starting its own before its first task's kernel.
    A numba without this entry point only costs the workers that time again."""
    try:
        from numba.core.registry import cpu_target

        cpu_target.target_context.refresh()
    except (ImportError, AttributeError):  # pragma: no cover - a numba that moved it
        pass


@contextmanager
def dask_executor(address: str) -> Iterator[Executor]:
    """An executor on the Dask cluster whose scheduler listens at ``address`` (``tcp://HOST:8786``).

    Raises
    ------
    InvalidParameter
        No scheduler answers at ``address`` within :data:`CONNECT_TIMEOUT_S` seconds.
    """
    from distributed import Client  # imported here: only a cluster build needs it

    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise InvalidParameter(f"scheduler {address}: cannot connect ({exc})") from exc
    try:
        # pure=False: a task's key is a random id, not a hash of its arguments. Dask would otherwise walk and
        # hash every contour of every task in this process (the client), a serial cost that took a second
        # core's worth of time from two workers; a build never submits the same task twice anyway.
        yield PickledTaskExecutor(client.get_executor(pure=False))
    finally:
        client.close()


#: Tasks of :func:`map_ordered` submitted ahead of the one being read: enough to keep every worker busy, few
#: enough that the inputs and results in flight stay a small, fixed share of a big build's memory.
AHEAD = 8


def map_ordered(
    executor: Executor | None,
    fn: Callable[..., R],
    tasks: Iterable[tuple[Any, ...]],
    ahead: int = AHEAD,
    *,
    weight: Callable[[tuple[Any, ...]], int] | None = None,
    budget: int | None = None,
    refetch: Callable[[tuple[Any, ...]], tuple[Any, ...]] | None = None,
) -> Iterator[R]:
    """``fn(*task)`` for every task, yielded in the tasks' order; in this process when ``executor`` is None.

    ``tasks`` is read lazily and at most ``ahead`` tasks are submitted and not yet yielded, so a generator of
    tasks that loads each task's data (a block's surfaces from a spool) holds only that many at once. With
    ``weight`` (a task's size in bytes, say) and ``budget``, no new task is read while those in flight weigh
    ``budget`` or more: a few heavy tasks then fill the look-ahead as many light ones do.

    A task that names its data by where it lies in a file of this process (:class:`~engine.payloads.FileSlice`)
    and lands on a worker that cannot read it (:class:`~engine.payloads.FileUnreachable`) is sent again as
    ``refetch`` makes it, with its data.
    """
    if executor is None:
        with threadpool_limits(1):
            for task in tasks:
                yield fn(*task)
        return
    pending: deque[tuple[Future[R], int, tuple[Any, ...]]] = deque()
    in_flight = 0
    for task in tasks:
        w = weight(task) if weight is not None else 0
        pending.append((executor.submit(fn, *task), w, task))
        in_flight += w
        while pending and (len(pending) >= ahead or (budget is not None and in_flight >= budget)):
            future, done, sent = pending.popleft()
            in_flight -= done
            yield _result(executor, fn, future, sent, refetch)
    while pending:
        future, _, sent = pending.popleft()
        yield _result(executor, fn, future, sent, refetch)


def _result(
    executor: Executor,
    fn: Callable[..., R],
    future: Future[R],
    task: tuple[Any, ...],
    refetch: Callable[[tuple[Any, ...]], tuple[Any, ...]] | None,
) -> R:
    """A task's result; sent again as ``refetch`` makes it when its worker could not read this process's file."""
    try:
        return future.result()
    except FileUnreachable:
        if refetch is None:
            raise
        return executor.submit(fn, *refetch(task)).result()


def lower_priority(niceness: int, *, idle: bool = False) -> None:
    """Add ``niceness`` to this process's; with ``idle``, also take Linux's idle scheduling class, where the
    process runs only on a core no other process wants and gives it up the moment one does (a nice process
    may finish its time slice first). Background work (builds, upload checks, the heavy render lane) takes
    it so that it cannot lengthen a map tile's render by sharing its core."""
    os.nice(niceness)
    if idle and hasattr(os, "SCHED_IDLE"):
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))


def cores() -> int:
    """Cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)
