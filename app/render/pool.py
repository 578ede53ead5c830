"""A bounded pool of render worker processes, with a deadline per request (docs/service.md, "Under load").

Why processes, not threads: a tile or ``/simplify`` is CPU work, much of it pure Python (Wang–Müller,
Visvalingam–Whyatt) that holds the GIL, and a thread cannot be stopped from outside. A worker process can:
when a request passes its deadline, its worker is killed and a fresh one started, so the work really stops
and the event loop (``/healthz`` included) never waits for it.

Three bounds, all settings: ``render_workers`` processes, ``render_queue`` requests waiting for one (beyond
that a request gets 503 at once, without queueing), and ``request_timeout_s`` from arrival to answer.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

from starlette.requests import Request

from app.render.jobs import HEAVY_NICENESS, LIGHT_NICENESS, MORPH_NICENESS, Job, RenderConfig, Rendered, worker_main
from app.settings import Settings
from engine.errors import CCSMError
from engine.serve.methods import Method

log = logging.getLogger("ccsm.render")

#: Seconds a new worker may take to start (import, open the store, pack the datasets) before it is
#: replaced; packing a large dataset takes seconds, a stuck start never ends.
START_TIMEOUT_S = 300.0
#: Seconds a job whose client hung up may still take before its worker is killed: a tile ends well within it
#: (its worker is kept), a long render is stopped.
CANCEL_GRACE_S = 1.0
#: Seconds a client is told to wait before trying again after a 503 from the pool.
RETRY_AFTER_S = 5


class RenderUnavailable(CCSMError):
    """The pool cannot answer this request now (busy, or the deadline passed): 503 with Retry-After."""


@dataclass(eq=False)  # identity: a worker is kept in a set
class Worker:
    """One worker process and the server's end of its pipe."""

    process: BaseProcess
    conn: Connection
    busy_since: float | None = field(default=None)

    def stop(self) -> None:
        """Kill the process (its work stops at once) and close the pipe."""
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.conn.close()


class RenderPool:
    """Runs :mod:`app.render.jobs` jobs in worker processes, each request within its deadline.

    Parameters
    ----------
    config
        What the workers open and how they draw.
    size
        Worker processes.
    queue
        Requests that may wait for a free worker; one more gets 503 at once.
    timeout_s
        Deadline of a request, seconds from :meth:`run` to its answer.
    niceness
        Niceness the workers add to the server's (app.render.jobs: LIGHT_NICENESS, HEAVY_NICENESS).
    """

    def __init__(
        self, config: RenderConfig, size: int, queue: int, timeout_s: float, niceness: int = LIGHT_NICENESS
    ) -> None:
        self.config = config
        self.niceness = niceness
        self.size = size
        self.queue = queue
        self.timeout_s = timeout_s
        # Never fork the server (it runs threads): a fork server, started clean once per server process with
        # the engine imported, forks each worker, so a replacement is ready in well under a second.
        self._ctx = multiprocessing.get_context("forkserver")
        # (The upload checks of app/datasets/uploads.py are forked from the same server.)
        self._ctx.set_forkserver_preload(["app.render.jobs", "app.render.preload", "app.datasets.upload_check"])
        # Threads that wait on pipes and start processes, so the event loop never blocks on either.
        self._threads = ThreadPoolExecutor(max_workers=2 * size + 2, thread_name_prefix="ccsm-render")
        self._idle: asyncio.Queue[Worker] = asyncio.Queue()
        self._workers: set[Worker] = set()
        self._lock = threading.Lock()
        self._admitted = 0
        self._closed = False
        self._settling: set[asyncio.Task[None]] = set()  # workers whose request was cancelled (kept referenced)
        self.replaced = 0

    # -- lifecycle ---------------------------------------------------------------------------------------
    async def start(self) -> None:
        """Start the workers and wait until they are warm (every stored dataset packed), so the first
        requests after a restart do not pay that inside their deadline. A worker that fails to start is
        retried in the background; the server starts anyway."""
        await asyncio.gather(*(self._spawn() for _ in range(self.size)), return_exceptions=True)

    def _spawn_soon(self) -> None:
        loop = asyncio.get_running_loop()
        task = loop.create_task(self._spawn())
        task.add_done_callback(_log_failure)

    async def _spawn(self) -> None:
        """Start one worker and put it in the idle queue once it says it is ready."""
        loop = asyncio.get_running_loop()
        worker = await loop.run_in_executor(self._threads, self._start_process)
        ready = await loop.run_in_executor(self._threads, _wait_ready, worker.conn, START_TIMEOUT_S)
        if self._closed:
            worker.stop()
            return
        if not ready:
            log.error("render worker %s did not start; starting another", worker.process.pid)
            self._retire(worker)
            await asyncio.sleep(1.0)
            self._spawn_soon()
            return
        self._idle.put_nowait(worker)

    def _start_process(self) -> Worker:
        parent, child = self._ctx.Pipe()
        process = self._ctx.Process(
            target=worker_main, args=(child, self.config, self.niceness), name="ccsm-render", daemon=True
        )
        process.start()
        child.close()
        worker = Worker(process, parent)
        with self._lock:
            self._workers.add(worker)
        return worker

    def _retire(self, worker: Worker) -> None:
        with self._lock:
            self._workers.discard(worker)
        self._threads.submit(worker.stop)

    async def close(self) -> None:
        """Stop every worker."""
        self._closed = True
        with self._lock:
            workers = list(self._workers)
            self._workers.clear()
        for worker in workers:
            worker.stop()
        self._threads.shutdown(wait=False, cancel_futures=True)

    # -- requests ----------------------------------------------------------------------------------------
    @property
    def in_flight(self) -> int:
        """Requests admitted and not yet answered (running or waiting)."""
        return self._admitted

    def pids(self) -> list[int]:
        """Process ids of the live workers (tests, the soak script)."""
        with self._lock:
            return [w.process.pid for w in self._workers if w.process.pid is not None]

    async def run(self, job: Job) -> Rendered:
        """Do ``job`` in a worker within the deadline.

        Raises
        ------
        RenderUnavailable
            Every worker busy and the queue full (at once), or the deadline passed (the work is stopped).
        CCSMError
            What the job itself raised (an unknown dataset, a contour too large, ...).
        """
        if self._admitted >= self.size + self.queue:
            raise RenderUnavailable(
                f"the service is busy ({self._admitted} requests in progress, limit "
                f"{self.size + self.queue}); try again in {RETRY_AFTER_S} s"
            )
        self._admitted += 1
        try:
            return await self._run_admitted(job, time.monotonic() + self.timeout_s)
        finally:
            self._admitted -= 1

    async def _run_admitted(self, job: Job, deadline: float) -> Rendered:
        try:
            worker = await asyncio.wait_for(self._idle.get(), max(deadline - time.monotonic(), 0.0))
        except TimeoutError:
            raise self._too_slow("no render worker became free", "") from None
        loop = asyncio.get_running_loop()
        worker.busy_since = time.monotonic()
        waited = worker.busy_since - (deadline - self.timeout_s)  # since the request arrived (run set the deadline)
        exchange = loop.run_in_executor(self._threads, _exchange, worker.conn, job, deadline - time.monotonic())
        try:
            status, value = await asyncio.shield(exchange)
        except asyncio.CancelledError:  # the client went away (app/http/disconnect.py): stop the work, cheaply
            self._settle_soon(worker, exchange)
            raise
        except _Late:
            self._replace(worker)
            raise self._too_slow("the answer was not ready", "; the work was stopped") from None
        except (EOFError, OSError):  # the worker died (killed from outside, out of memory)
            self._replace(worker)
            raise RenderUnavailable(
                f"the render worker stopped while drawing this; try again in {RETRY_AFTER_S} s"
            ) from None
        except BaseException:  # anything else (an answer that does not unpickle): the worker's state is unknown
            self._replace(worker)
            raise
        worker.busy_since = None
        self._idle.put_nowait(worker)
        if status == "ok":
            return replace(value, wait_s=waited)
        raise value

    def _settle_soon(self, worker: Worker, exchange: asyncio.Future[tuple[str, Any]]) -> None:
        """After a cancelled request: a job that ends within CANCEL_GRACE_S gives its worker back (a fresh
        worker costs more than most tiles, and a client that asks and hangs up must not make the pool
        respawn), one that runs on is stopped by killing its worker."""

        async def settle() -> None:
            try:
                await asyncio.wait_for(exchange, CANCEL_GRACE_S)
            except BaseException:  # still running, late or dead: stop it
                self._replace(worker)
                return
            worker.busy_since = None
            self._idle.put_nowait(worker)

        task = asyncio.get_running_loop().create_task(settle())
        self._settling.add(task)
        task.add_done_callback(self._settling.discard)

    def _replace(self, worker: Worker) -> None:
        """Kill a worker whose job is late or lost and start a fresh one in its place."""
        self.replaced += 1
        log.warning("render worker %s stopped (deadline or failure); starting another", worker.process.pid)
        self._retire(worker)
        if not self._closed:
            self._spawn_soon()

    def _too_slow(self, what: str, then: str) -> RenderUnavailable:
        return RenderUnavailable(
            f"{what} within the {self.timeout_s:g} s deadline (request_timeout_s){then}; "
            f"try again in {RETRY_AFTER_S} s"
        )


def _wait_ready(conn: Connection, timeout: float) -> bool:
    """True once a new worker sends ``ready`` (False: it died or took longer than ``timeout``)."""
    try:
        if not conn.poll(timeout):
            return False
        status, _ = conn.recv()
    except (EOFError, OSError):
        return False
    return bool(status == "ready")


class _Late(Exception):
    """A job's answer did not come before its deadline."""


def _exchange(conn: Connection, job: Job, timeout: float) -> tuple[str, Any]:
    """Send a job, wait for its answer at most ``timeout`` seconds (runs in a pool thread)."""
    conn.send(job)
    if not conn.poll(max(timeout, 0.0)):
        raise _Late
    return conn.recv()  # type: ignore[no-any-return]


def _log_failure(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("starting a render worker failed", exc_info=task.exception())


@dataclass
class RenderLanes:
    """Three pools, so slow requests cannot hold up quick ones: ``light`` draws ccsm and original tiles
    (milliseconds each), ``morph`` draws morph tiles (a morph tile checks every pair of its contours for a
    crossing through the level: up to half a second on a dense tile, so a plain tile must not queue behind
    one), ``heavy`` draws baseline tiles and ``/simplify`` (a whole dataset, or a per-request simplifier).
    Each has its own workers, queue and deadline."""

    light: RenderPool
    heavy: RenderPool
    morph: RenderPool

    def for_tile(self, method: Method) -> RenderPool:
        """The lane of a tile drawn with ``method``: the heavy one for a method that simplifies whole contours
        on each request (pure Python, Wang–Müller super-linear), where a ccsm or original tile only cuts
        stored rows."""
        return self.heavy if method.simplifies_per_request else self.light

    def all(self) -> tuple[RenderPool, ...]:
        """Every lane."""
        return (self.light, self.morph, self.heavy)

    async def start(self) -> None:
        """Start every lane's workers (they warm up side by side)."""
        await asyncio.gather(*(lane.start() for lane in self.all()))

    async def close(self) -> None:
        """Stop every worker."""
        for lane in self.all():
            await lane.close()


def render_lanes_for(settings: Settings) -> RenderLanes:
    """The lanes the settings ask for (not started)."""
    config = render_config_for(settings)
    queue, timeout = settings.render_queue, settings.request_timeout_s
    return RenderLanes(
        light=RenderPool(config, settings.render_workers, queue, timeout),
        heavy=RenderPool(config, settings.heavy_render_workers, queue, timeout, HEAVY_NICENESS),
        morph=RenderPool(config, settings.morph_render_workers, queue, timeout, MORPH_NICENESS),
    )


def render_config_for(settings: Settings) -> RenderConfig:
    """What the workers need from the settings."""
    from engine.serve.renderer import TileOptions

    return RenderConfig(
        store_path=settings.store_path,
        tile=TileOptions(
            extent=settings.tile_extent,
            buffer_px=settings.tile_buffer,
            min_zoom=settings.min_zoom,
            max_zoom=settings.max_zoom,
        ),
        contour_cache_bytes=settings.contour_cache_mb << 20,
        baseline_cache_entries=settings.baseline_cache_entries,
        wm_max_vertices=settings.wm_max_vertices,
        morph_cache_bytes=settings.morph_cache_mb << 20,
        head_cache_bytes=settings.head_cache_mb << 20,
        store_mmap_bytes=settings.store_mmap_mb << 20,
    )


def get_render_lanes(request: Request) -> RenderLanes:
    """The app's render lanes (a request dependency)."""
    return request.app.state.render_lanes  # type: ignore[no-any-return]
