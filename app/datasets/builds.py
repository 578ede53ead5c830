"""Builds in processes of their own, a bounded number at a time, the rest queued (docs/service.md, "Builds").

Each build is ``python -m engine.build.job`` in a new session (its own process group), so

- the memory a build takes goes back to the system when it ends (the server stays near its baseline);
- deleting a dataset stops its build by ending the group (the build's own worker processes included);
- stopping the server ends every build, and no build inherits the server's listening socket.

At most ``max_builds`` run at once; up to ``build_queue`` wait; one more is refused (:class:`BuildQueueFull`).
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from app.errors import BuildQueueFull
from engine.build.job import BuildJob

log = logging.getLogger("ccsm.builds")

#: Seconds a build process has to stop after SIGTERM before it is killed.
STOP_GRACE_S = 5.0


@dataclass
class _Running:
    job: BuildJob
    proc: subprocess.Popen[bytes]


class BuildRunner:
    """Runs :class:`BuildJob` s in child processes, ``max_builds`` at a time.

    ``on_exit(job, returncode)`` is called (in a watcher thread) when a build process ends on its own.
    """

    def __init__(self, max_builds: int, queue_size: int, on_exit: Callable[[BuildJob, int], None]) -> None:
        self.max_builds = max_builds
        self.queue_size = queue_size
        self._on_exit = on_exit
        self._lock = threading.Lock()
        self._idle = threading.Condition(self._lock)
        self._pending: deque[BuildJob] = deque()
        self._running: dict[str, _Running] = {}
        self._stopped = False

    def submit(self, job: BuildJob, *, limit_queue: bool = True) -> None:
        """Start the job now or queue it; BuildQueueFull when the queue is full (``limit_queue``: configured
        sources built at start always wait their turn)."""
        with self._lock:
            if self._stopped:
                raise BuildQueueFull("the service is stopping")
            if len(self._running) < self.max_builds:
                self._start(job)
            elif not limit_queue or len(self._pending) < self.queue_size:
                self._pending.append(job)
            else:
                raise BuildQueueFull(
                    f"{len(self._running)} builds are running and {len(self._pending)} are waiting "
                    "(CCSM_MAX_BUILDS, CCSM_BUILD_QUEUE); try again later"
                )

    def _start(self, job: BuildJob) -> None:
        proc = subprocess.Popen(
            [sys.executable, "-m", "engine.build.job"],
            stdin=subprocess.PIPE,
            start_new_session=True,  # its own process group: ended as a whole on delete and shutdown
            close_fds=True,
        )
        assert proc.stdin is not None
        proc.stdin.write(job.to_json().encode() + b"\n")
        proc.stdin.close()
        self._running[job.dataset] = _Running(job, proc)
        threading.Thread(target=self._watch, args=(job, proc), name=f"ccsm-build-{job.dataset}", daemon=True).start()

    def _watch(self, job: BuildJob, proc: subprocess.Popen[bytes]) -> None:
        code = proc.wait()
        with self._lock:
            if self._running.get(job.dataset, None) is not None and self._running[job.dataset].proc is proc:
                del self._running[job.dataset]
            ended_by_us = self._stopped
        if not ended_by_us:
            try:
                self._on_exit(job, code)
            except Exception:
                log.exception("after the build of %s", job.dataset)
        with self._lock:
            while not self._stopped and self._pending and len(self._running) < self.max_builds:
                self._start(self._pending.popleft())
            self._idle.notify_all()

    def cancel(self, dataset: str) -> bool:
        """Drop a queued build or end a running one; True if there was one."""
        with self._lock:
            for job in list(self._pending):
                if job.dataset == dataset:
                    self._pending.remove(job)
                    return True
            running = self._running.get(dataset)
        if running is None:
            return False
        _end_group(running.proc)
        return True

    def busy(self) -> bool:
        """True while a build runs or waits."""
        with self._lock:
            return bool(self._running or self._pending)

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until no build runs or waits (tests, CLI); False on timeout."""
        with self._idle:
            return self._idle.wait_for(lambda: not self._running and not self._pending, timeout)

    def shutdown(self) -> None:
        """Forget the queue and end every running build (the server is stopping)."""
        with self._lock:
            self._stopped = True
            self._pending.clear()
            running = list(self._running.values())
        for r in running:
            _end_group(r.proc)


def _end_group(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM the build's process group, SIGKILL it after STOP_GRACE_S."""
    for sig, wait in ((signal.SIGTERM, STOP_GRACE_S), (signal.SIGKILL, STOP_GRACE_S)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(wait)
            # The leader is gone; its workers may linger a moment: end the rest of the group too.
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            return
        except subprocess.TimeoutExpired:
            continue
        return
