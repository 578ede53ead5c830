"""Scratch files of a build in progress: SQLite files beside the store that hold what the build has read or
made until it is written, so a build's memory does not grow with the dataset (docs/design.md section 6).

A scratch file is not the store: no server reads it, it is written without a journal or fsync (a killed build
only leaves it to be removed) and it is deleted when the build ends. Its name carries the host and process
id of the build that writes it, so the next build in that directory removes one whose build no longer runs.
"""

from __future__ import annotations

import os
import sqlite3
import tempfile
from pathlib import Path

from engine.errors import StoreError

#: Name prefix of scratch files, followed by the host and the process id of the build that writes it.
SCRATCH_PREFIX = ".ccsm-spool-"


def host_name() -> str:
    """This machine's name, as builds record it."""
    return os.uname().nodename if hasattr(os, "uname") else "localhost"


def pid_alive(pid: int) -> bool:
    """Whether a process of this id runs on this machine (one we may not signal counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_scratch(directory: str | os.PathLike[str]) -> list[Path]:
    """Remove the scratch files of this host's builds that no longer run; the paths removed."""
    removed = []
    for path in Path(directory).glob(f"{SCRATCH_PREFIX}{host_name()}-*.sqlite"):
        pid = path.name[len(SCRATCH_PREFIX) + len(host_name()) + 1 :].split("-", 1)[0]
        if pid.isdigit() and not pid_alive(int(pid)):
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def open_scratch(directory: str | os.PathLike[str], schema: str) -> tuple[Path, sqlite3.Connection]:
    """A new scratch file in ``directory`` with the tables of ``schema`` (stale ones removed first).

    Raises
    ------
    StoreError
        The file cannot be made there (a missing or read-only directory, a full disk).
    """
    remove_stale_scratch(directory)
    prefix = f"{SCRATCH_PREFIX}{host_name()}-{os.getpid()}-"
    try:
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=".sqlite", dir=directory)
    except OSError as exc:
        raise StoreError(f"cannot make the build's scratch file in {directory}: {exc.strerror}") from exc
    os.close(fd)
    con = sqlite3.connect(name)
    # Scratch data: no journal, no fsync. A crash loses only this file, which nothing else reads.
    con.executescript(f"PRAGMA journal_mode=OFF; PRAGMA synchronous=OFF; PRAGMA cache_size=-16000; {schema}")
    return Path(name), con
