"""Ending the child processes (servers, dask schedulers and workers) that tests and benchmarks start."""

from __future__ import annotations

import subprocess
from typing import Any


def stop_process(proc: subprocess.Popen[Any], grace_s: float = 20.0) -> None:
    """Ask ``proc`` to end (SIGTERM) and wait; kill it if it is still running after ``grace_s`` seconds."""
    proc.terminate()
    try:
        proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
