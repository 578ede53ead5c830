"""A build on 16 and 64 Dask workers, and for 10^8 and 10^10 vertices, predicted from one measured build
(issue 26 item 3). It prints numbers: it is a model, not a test.

1. **Measure.** One build of a DEM (bench_scale.py's fractal terrain) runs on one worker process through an
   executor that times every task where it runs: its CPU seconds, and the pickled size of what goes in and what
   comes back. The build process (the client) is timed too: its CPU in each phase (a run of tasks of one kind:
   tracing windows, building chunks, checking blocks, rebuilding, making rows, finding label candidates), from
   the first task of the phase to the first of the next. One worker leaves the other core to the client, so the
   tasks' times are not inflated by it.
2. **Model.** The set is ``k`` times larger (k = vertices / measured vertices): ``k`` times the tasks of each
   phase, of the same sizes. A phase on N workers takes the longest of
   - the workers' share: ``k x`` its tasks' CPU / N, plus its longest task (list scheduling is within that of
     optimal);
   - the client: today every result comes back to the client, which does its serial part of the phase
     (``k x`` its CPU) and reads every byte the tasks send back (at ``--client-mb-s``);
   - the scheduler: ``--sched-ms`` of its CPU per task (Dask's documented order of magnitude);
   - the store's writer: today the rows of every task go into one SQLite file, each worker merging its own
     shard under the file's one write lock, so the merges run one at a time: ``k x`` the seconds the tasks
     spent inside them (``writer s``).
   The second scenario, *shards*, is issue 26 item 2: each block's task traces, builds, repairs, labels and
   writes its own shard, so the client's per-contour CPU moves to the workers (added to their share), the client
   only plans (``--plan-ms`` per task) and nothing comes back but a small record; the export then merges the
   shards in one streaming pass at ``--merge-mb-s``, on the archive's size.

Every assumption is an option and printed with the result. What the model leaves out: disk bandwidth of the
shards and the network between workers are not modelled beyond the client's read rate and the writer's
measured seconds.

Usage: python bench/simulate_cluster.py [--side 1024] [--interval 20] [--workers 16,64] [--vertices 1e8,1e10]
"""

from __future__ import annotations

import argparse
import os
import pickle
import resource
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))

#: The archive's bytes per input vertex, from bench_dem_to_map.py on the 16x terrain (33.78 MB / 2,613,572).
ARCHIVE_BYTES_PER_VERTEX = 33.78e6 / 2_613_572


def timed_call(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> tuple[Any, ...]:
    """Run one task where it is sent; its result, CPU seconds, the pickled sizes of its input and output, and
    the seconds it spent merging rows into the store (under the store's one write lock)."""
    import engine.store.shard as shard

    merging = [0.0]
    real_merge = shard.merge_shard

    def timed_merge(*a: Any, **k: Any) -> bool:
        start = time.perf_counter()
        try:
            return real_merge(*a, **k)
        finally:
            merging[0] += time.perf_counter() - start

    size_in = len(pickle.dumps((fn, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL))
    shard.merge_shard = timed_merge
    try:
        cpu0 = time.process_time()
        result = fn(*args, **kwargs)
        cpu = time.process_time() - cpu0
    finally:
        shard.merge_shard = real_merge
    size_out = len(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    return result, cpu, size_in, size_out, merging[0]


@dataclass
class Task:
    name: str
    client_cpu_at_submit: float
    cpu: float = 0.0
    size_in: int = 0
    size_out: int = 0
    writer: float = 0.0


@dataclass
class TimingExecutor(Executor):
    """Another executor, with every task timed where it runs (:func:`timed_call`)."""

    inner: Executor
    tasks: list[Task] = field(default_factory=list)

    def submit(self, fn, /, *args, **kwargs):  # type: ignore[no-untyped-def]  # noqa: ANN001, ANN002, ANN003, ANN201
        name = getattr(fn, "__name__", None) or getattr(getattr(fn, "func", None), "__name__", "task")
        task = Task(name, time.process_time())
        self.tasks.append(task)
        outer: Future[Any] = Future()

        def done(inner: Future[Any]) -> None:
            try:
                result, task.cpu, task.size_in, task.size_out, task.writer = inner.result()
            except BaseException as exc:  # noqa: BLE001 - handed on to whoever waits for the task
                outer.set_exception(exc)
            else:
                outer.set_result(result)

        self.inner.submit(timed_call, fn, args, kwargs).add_done_callback(done)
        return outer

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:  # noqa: D102
        self.inner.shutdown(wait=wait, cancel_futures=cancel_futures)


@dataclass
class Phase:
    name: str
    tasks: int
    worker_cpu: float
    longest: float
    client_cpu: float
    bytes_back: int
    bytes_out: int
    writer: float


def measure(dem: Path, interval: float) -> tuple[list[Phase], int, float, float, int]:
    """Build ``dem`` on one timed worker: the phases, input vertices, client CPU, wall seconds, store bytes."""
    from engine.build.datasets import SourceSpec, build_dataset
    from engine.parallel import local_pool
    from engine.store.store import CCSStore

    with tempfile.TemporaryDirectory() as tmp, local_pool(1) as pool:
        executor = TimingExecutor(pool)
        store = CCSStore(Path(tmp) / "s.sqlite")
        start_cpu, start = time.process_time(), time.perf_counter()
        info, _ = build_dataset(store, SourceSpec(dem, "bench", dem.stem, interval=interval), executor=executor)
        end_cpu, wall = time.process_time(), time.perf_counter() - start
        store.close()
        store_bytes = sum(f.stat().st_size for f in Path(tmp).glob("s.sqlite*"))
    tasks = executor.tasks
    # Runs of one kind of task, in submission order; each run's client CPU lasts to the next run's first task.
    runs: list[list[Task]] = []
    for t in tasks:
        if runs and runs[-1][0].name == t.name:
            runs[-1].append(t)
        else:
            runs.append([t])
    marks = [start_cpu] + [r[0].client_cpu_at_submit for r in runs[1:]] + [end_cpu]
    phases = [
        Phase(
            r[0].name,
            len(r),
            sum(t.cpu for t in r),
            max(t.cpu for t in r),
            marks[i + 1] - marks[i],
            sum(t.size_out for t in r),
            sum(t.size_in for t in r),
            sum(t.writer for t in r),
        )
        for i, r in enumerate(runs)
    ]
    return phases, int(info.n_vertices), end_cpu - start_cpu, wall, store_bytes


def merged(phases: list[Phase]) -> list[Phase]:
    """One line per kind of task (the repair's rounds alternate checks and rebuilds)."""
    out: dict[str, Phase] = {}
    for p in phases:
        if p.name in out:
            q = out[p.name]
            out[p.name] = Phase(
                p.name,
                q.tasks + p.tasks,
                q.worker_cpu + p.worker_cpu,
                max(q.longest, p.longest),
                q.client_cpu + p.client_cpu,
                q.bytes_back + p.bytes_back,
                q.bytes_out + p.bytes_out,
                q.writer + p.writer,
            )
        else:
            out[p.name] = p
    return list(out.values())


def predict(phases: list[Phase], k: float, workers: int, args: argparse.Namespace, shards: bool) -> float:
    """Seconds of a build ``k`` times the measured one on ``workers`` workers (module docstring, 2.)."""
    total = 0.0
    for p in phases:
        tasks = p.tasks * k
        sched = tasks * args.sched_ms / 1000
        if shards:  # each block writes its own file: no shared writer
            work = (p.worker_cpu + p.client_cpu) * k / workers + p.longest
            client = tasks * args.plan_ms / 1000
            writer = 0.0
        else:
            work = p.worker_cpu * k / workers + p.longest
            client = p.client_cpu * k + p.bytes_back * k / (args.client_mb_s * 1e6)
            writer = p.writer * k
        total += max(work, client, sched, writer)
    return total


def hours(seconds: float) -> str:
    return f"{seconds / 3600:10.2f} h" if seconds >= 3600 else f"{seconds:10.1f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--side", type=int, default=1024, help="cells a side of the fractal terrain (1024: 4x)")
    ap.add_argument("--interval", type=float, default=20.0)
    ap.add_argument("--workers", default="16,64")
    ap.add_argument("--vertices", default="1e8,1e10")
    ap.add_argument("--sched-ms", type=float, default=1.0, help="scheduler CPU per task, ms [1]")
    ap.add_argument("--plan-ms", type=float, default=0.2, help="client CPU per task with shards, ms [0.2]")
    ap.add_argument("--client-mb-s", type=float, default=500.0, help="client's read rate of results, MB/s [500]")
    ap.add_argument("--merge-mb-s", type=float, default=200.0, help="shard merge into the archive, MB/s [200]")
    args = ap.parse_args()
    from profile_build import dem as make_dem

    dem = make_dem(args.side)
    phases, vertices, client_cpu, wall, store_bytes = measure(dem, args.interval)
    worker_cpu = sum(p.worker_cpu for p in phases)
    print(
        f"measured: {dem.name} at {args.interval:g} m, {vertices:,} input vertices, 1 worker + the client on "
        f"{os.cpu_count()} cores: {wall:.1f} s; worker CPU {worker_cpu:.1f} s, client CPU {client_cpu:.1f} s "
        f"(client share {client_cpu / (client_cpu + worker_cpu):.1%}); store {store_bytes / 1e6:.1f} MB; "
        f"peak RSS of the client {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )
    head = f"{'phase (task)':>28} {'tasks':>6} {'worker CPU s':>12} {'longest s':>9} {'client CPU s':>12}"
    print(f"{head} {'MB back':>8} {'writer s':>8}")
    for p in merged(phases):
        print(
            f"{p.name:>28} {p.tasks:6d} {p.worker_cpu:12.2f} {p.longest:9.3f} {p.client_cpu:12.2f} "
            f"{p.bytes_back / 1e6:8.1f} {p.writer:8.2f}"
        )
    print(
        f"assumptions: scheduler {args.sched_ms} ms/task; with shards the client plans {args.plan_ms} ms/task; "
        f"client reads results at {args.client_mb_s:g} MB/s; shards merge at {args.merge_mb_s:g} MB/s; archive "
        f"{ARCHIVE_BYTES_PER_VERTEX:.1f} B/vertex, store {store_bytes / vertices:.0f} B/vertex"
    )
    check = predict(phases, 1.0, 1, args, shards=False)
    print(f"model check: today's design on 1 worker at the measured size {check:.1f} s, measured {wall:.1f} s")
    counts = [int(w) for w in args.workers.split(",")]
    print(f"{'vertices':>10} {'scenario':>8} " + " ".join(f"{f'{n} workers':>13}" for n in [1, 2, *counts]))
    for v in [float(vertices), *(float(x) for x in args.vertices.split(","))]:
        k = v / vertices
        merge = v * ARCHIVE_BYTES_PER_VERTEX / (args.merge_mb_s * 1e6)
        for shards in (False, True):
            cells = [predict(phases, k, n, args, shards) + (merge if shards else 0.0) for n in [1, 2, *counts]]
            label = "shards" if shards else "today"
            print(f"{v:10.1e} {label:>8} " + " ".join(f"{hours(c):>13}" for c in cells))
    print(
        f"store at 1e10 vertices today: {1e10 * store_bytes / vertices / 1e12:.1f} TB in one SQLite file; "
        f"archive {1e10 * ARCHIVE_BYTES_PER_VERTEX / 1e9:.0f} GB"
    )


if __name__ == "__main__":
    main()
