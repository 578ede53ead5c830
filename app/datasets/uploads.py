"""Uploads off the event loop (docs/service.md, "Uploads"): the body streamed to a file, the file checked in a
process of its own.

- :func:`receive_upload` writes the request body to a file of the upload folder as it arrives, a bounded
  buffer at a time, and refuses it (413) as soon as it passes the limit; the server never holds a whole
  upload in memory, and the writes run in a thread.
- :class:`UploadChecker` parses and checks that file in a short-lived child process (:mod:`app.datasets.upload_check`),
  ``size`` at a time with ``queue`` more waiting (one more gets 429), each within a deadline. The server
  awaits the answer, so the event loop never parses, and the memory a parse takes returns to the system
  when its process ends. Bad input still gets its 4xx before anything is kept.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import threading
import uuid
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import IO, Any

from fastapi.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request

from app.datasets.upload_check import CheckedUpload, UploadCheck, checker_main
from app.errors import ClientGone, UploadCheckFailed, UploadQueueFull, UploadTooLarge
from app.settings import Settings
from engine.errors import StoreUnwritable
from engine.store.connection import unwritable_reason

log = logging.getLogger("ccsm.uploads")

#: Upload files are written under this prefix (and the server's pid) until their dataset id is reserved.
INCOMING_PREFIX = ".incoming-"
#: Bytes of an upload held in memory before they are written out (bounds the server's memory per upload).
WRITE_BUFFER_BYTES = 1 << 20


def incoming_path(folder: Path) -> Path:
    """A new file name for an upload being received (the pid lets a restart tell live files from stale)."""
    return folder / f"{INCOMING_PREFIX}{os.getpid()}-{uuid.uuid4().hex[:8]}.geojson"


def _unwritable(exc: OSError) -> Exception:
    reason = unwritable_reason(exc)
    return exc if reason is None else StoreUnwritable(f"the upload cannot be saved: {reason}")


async def receive_upload(request: Request, folder: Path, limit: int) -> Path:
    """Stream the request body into a new file of ``folder``; its path.

    Raises
    ------
    UploadTooLarge
        The body (declared or received) exceeds ``limit`` bytes; nothing is kept.
    StoreUnwritable
        The folder cannot be written (full disk, read-only); nothing is kept.
    """
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > limit:
        raise UploadTooLarge(f"upload of {int(declared)} bytes exceeds the limit of {limit} bytes")
    path = incoming_path(folder)
    try:
        fh = await run_in_threadpool(_open_new, path)
    except OSError as exc:
        raise _unwritable(exc) from exc
    try:
        await _copy_body(request, fh, limit)
        await run_in_threadpool(fh.close)
    except BaseException as exc:
        fh.close()
        path.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise _unwritable(exc) from exc
        raise
    return path


def _open_new(path: Path) -> IO[bytes]:
    path.parent.mkdir(parents=True, exist_ok=True)
    return open(path, "xb")


async def _copy_body(request: Request, fh: IO[bytes], limit: int) -> None:
    size = 0
    buffer: list[bytes] = []
    buffered = 0
    try:
        async for chunk in request.stream():
            size += len(chunk)
            if size > limit:
                raise UploadTooLarge(f"upload exceeds the limit of {limit} bytes")
            buffer.append(chunk)
            buffered += len(chunk)
            if buffered >= WRITE_BUFFER_BYTES:
                await run_in_threadpool(fh.write, b"".join(buffer))
                buffer, buffered = [], 0
    except ClientDisconnect as exc:  # it hung up, or stalled past CCSM_READ_TIMEOUT_S: a 499, no traceback
        raise ClientGone("the client stopped sending its upload") from exc
    if buffer:
        await run_in_threadpool(fh.write, b"".join(buffer))


class UploadChecker:
    """Runs :func:`app.datasets.upload_check.check_upload` in child processes, ``size`` at a time.

    Parameters
    ----------
    size
        Checks running at once (each in a process of its own: this bounds the memory checks take).
    queue
        Checks that may wait for a slot; one more is refused at once (:class:`UploadQueueFull`, 429).
    timeout_s
        Seconds a check may run; then its process is killed (:class:`UploadCheckFailed`, 503).
    """

    def __init__(self, size: int, queue: int, timeout_s: float) -> None:
        self.size = size
        self.queue = queue
        self.timeout_s = timeout_s
        # Forked from the same fork server as the render workers (engine imported once): a check starts in
        # milliseconds, and the server, which runs threads, is never forked itself.
        self._ctx = multiprocessing.get_context("forkserver")
        self._threads = ThreadPoolExecutor(max_workers=size, thread_name_prefix="ccsm-upload-check")
        self._slots: asyncio.Semaphore | None = None
        self._admitted = 0
        self._running: set[BaseProcess] = set()
        self._lock = threading.Lock()

    @property
    def in_flight(self) -> int:
        """Checks admitted and not yet answered (running or waiting)."""
        return self._admitted

    async def check(self, job: UploadCheck) -> CheckedUpload:
        """Check one upload in a child process.

        Raises
        ------
        UploadQueueFull
            ``size`` checks run and ``queue`` wait already.
        UploadCheckFailed
            The check passed its deadline or its process died (killed, out of memory).
        MalformedUpload, SourceError, InvalidParameter
            What the check found wrong with the upload.
        """
        if self._admitted >= self.size + self.queue:
            raise UploadQueueFull(
                f"{self._admitted} uploads are being checked or wait for it (CCSM_UPLOAD_CHECKS, "
                "CCSM_UPLOAD_CHECK_QUEUE); try again later"
            )
        if self._slots is None:
            self._slots = asyncio.Semaphore(self.size)
        self._admitted += 1
        try:
            async with self._slots:
                status, value = await self._in_child(job)
        finally:
            self._admitted -= 1
        if status == "ok":
            return value  # type: ignore[no-any-return]
        raise value

    async def _in_child(self, job: UploadCheck) -> tuple[str, Any]:
        parent, child = self._ctx.Pipe(duplex=False)
        process = self._ctx.Process(target=checker_main, args=(child, job), name="ccsm-upload-check", daemon=True)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(self._threads, self._start, process, child)
        try:
            return await loop.run_in_executor(self._threads, self._wait, process, parent)
        except asyncio.CancelledError:  # the client went away: the check stops too
            process.kill()
            raise

    def _start(self, process: BaseProcess, child_end: Connection) -> None:
        process.start()
        child_end.close()  # the child has its own copy; without ours, the parent sees EOF if the child dies
        with self._lock:
            self._running.add(process)

    def _wait(self, process: BaseProcess, conn: Connection) -> tuple[str, Any]:
        """Wait for the check's answer (in a pool thread); kill the check past the deadline."""
        try:
            if not conn.poll(self.timeout_s):
                process.kill()
                raise UploadCheckFailed(
                    f"checking the upload took longer than {self.timeout_s:g} s (CCSM_UPLOAD_CHECK_TIMEOUT_S); "
                    "the check was stopped"
                )
            try:
                answer: tuple[str, Any] = conn.recv()
            except (EOFError, OSError):
                process.join(5)
                log.error("upload check process %s ended with status %s", process.pid, process.exitcode)
                raise UploadCheckFailed(
                    f"the upload check process ended with status {process.exitcode} (out of memory?); "
                    "try again later"
                ) from None
            return answer
        finally:
            conn.close()
            process.join(5)
            with self._lock:
                self._running.discard(process)

    def pids(self) -> list[int]:
        """Process ids of the checks running now (tests)."""
        with self._lock:
            return [p.pid for p in self._running if p.pid is not None]

    def close(self) -> None:
        """Stop every running check (the server is stopping)."""
        with self._lock:
            running = list(self._running)
        for process in running:
            process.kill()
        self._threads.shutdown(wait=False, cancel_futures=True)



def upload_checker_for(settings: Settings) -> UploadChecker:
    """The checker the settings ask for."""
    return UploadChecker(settings.upload_checks, settings.upload_check_queue, settings.upload_check_timeout_s)


def get_upload_checker(request: Request) -> UploadChecker:
    """The app's upload checker (made by the lifespan)."""
    return request.app.state.upload_checker  # type: ignore[no-any-return]
