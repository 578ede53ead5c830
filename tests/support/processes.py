"""Ending the child processes (servers, dask schedulers and workers) that tests and benchmarks start."""

from __future__ import annotations

import subprocess
from typing import Any

import psutil


def stop_process(proc: subprocess.Popen[Any], grace_s: float = 20.0) -> None:
    """Ask ``proc`` to end (SIGTERM) and wait; kill it if it is still running after ``grace_s`` seconds."""
    proc.terminate()
    try:
        proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def fork_server(pid: int) -> psutil.Process | None:
    """The child of process ``pid`` that runs a multiprocessing fork server, or None. A child that has just
    ended (a build process the server has not reaped yet) is passed over: asking for its command line raises."""
    for child in psutil.Process(pid).children():
        try:
            command = " ".join(child.cmdline())
        except psutil.NoSuchProcess:  # ZombieProcess too
            continue
        if "forkserver" in command:
            return child
    return None


def forked_processes(pid: int) -> list[psutil.Process]:
    """The live processes forked from the fork server of process ``pid`` (none without one): a server's render
    workers and upload checks."""
    forks = fork_server(pid)
    if forks is None:
        return []
    return [p for p in forks.children() if p.status() != psutil.STATUS_ZOMBIE]
