"""Build bookkeeping in the store file: which dataset ids are claimed by a build, its progress, its failure.

The ``builds`` table (:mod:`engine.store.schema`) holds one row per build that runs or failed; a stored dataset
has none (the write that stores it removes it, :meth:`engine.store.store.CCSStore.save`). Claiming an id, and
seeing a build deleted meanwhile, happen in the store's write transactions, so they hold across processes. A
build is owned by the host and process that record it: a 'building' row whose process is gone is a failure.
"""

from __future__ import annotations

import os
import sqlite3
import time
from dataclasses import dataclass

from engine.scratch import host_name, pid_alive
from engine.store.connection import StoreFile


@dataclass(frozen=True)
class BuildStatus:
    """Progress of a build in progress, or the error of a failed one (``state``: building or failed)."""

    dataset: str
    state: str
    done: int
    total: int
    error: str | None
    pid: int
    host: str
    started: float
    updated: float


def is_building(cur: sqlite3.Cursor, dataset: str) -> bool:
    """Whether a build of ``dataset`` is recorded as running (inside a write transaction: still so at commit)."""
    row = cur.execute("SELECT state FROM builds WHERE dataset=?", (dataset,)).fetchone()
    return row is not None and row[0] == "building"


def has_build(cur: sqlite3.Cursor, dataset: str) -> bool:
    """Whether any build of ``dataset`` is recorded (running or failed)."""
    return cur.execute("SELECT 1 FROM builds WHERE dataset=?", (dataset,)).fetchone() is not None


def forget_build(cur: sqlite3.Cursor, dataset: str) -> None:
    """Remove the build row of ``dataset`` (none: nothing happens)."""
    cur.execute("DELETE FROM builds WHERE dataset=?", (dataset,))


def _taken(cur: sqlite3.Cursor, dataset: str) -> bool:
    stored = cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
    return stored or has_build(cur, dataset)


def _insert_build(cur: sqlite3.Cursor, dataset: str, total: int) -> None:
    now = time.time()
    cur.execute(
        "INSERT INTO builds VALUES (?,?,?,?,?,?,?,?,?)",
        (dataset, "building", 0, int(total), None, os.getpid(), host_name(), now, now),
    )


class BuildBook(StoreFile):
    """The builds recorded in a store file (see the module's text); :class:`~engine.store.store.CCSStore` is
    one, beside the datasets it stores."""

    def reserve(self, dataset: str, total: int = 0) -> bool:
        """Claim a new dataset id for a build, atomically across threads and processes.

        True when the id was free (neither stored nor building nor failed): a 'building' row now holds it.
        """
        with self._write() as cur:
            if _taken(cur, dataset):
                return False
            _insert_build(cur, dataset, total)
        return True

    def reserve_free(self, base: str, total: int = 0) -> str:
        """Claim ``base``, else ``base-2``, ``base-3``, ... (the first free one), in one transaction."""
        with self._write() as cur:
            ident, n = base, 2
            while _taken(cur, ident):
                ident, n = f"{base}-{n}", n + 1
            _insert_build(cur, ident, total)
        return ident

    def fail_build(self, dataset: str, error: str) -> bool:
        """Mark a running build failed with a reason; False (nothing written) when it was deleted meanwhile."""
        with self._write() as cur:
            cur.execute(
                "UPDATE builds SET state='failed', error=?, updated=? WHERE dataset=? AND state='building'",
                (error, time.time(), dataset),
            )
            return cur.rowcount > 0

    def update_build_progress(self, dataset: str, done: int, total: int) -> bool:
        """Record progress of a running build from the process doing it; False when the build was deleted."""
        with self._write() as cur:
            cur.execute(
                "UPDATE builds SET done=?, total=?, pid=?, host=?, updated=? WHERE dataset=? AND state='building'",
                (int(done), int(total), os.getpid(), host_name(), time.time(), dataset),
            )
            return cur.rowcount > 0

    def set_build_status(
        self, dataset: str, state: str, done: int = 0, total: int = 0, error: str | None = None
    ) -> None:
        """Record a build's progress (visible to every process reading the store)."""
        now = time.time()
        with self._write() as cur:
            row = cur.execute("SELECT started FROM builds WHERE dataset=?", (dataset,)).fetchone()
            started = now if row is None or state == "building" and done == 0 else row[0]
            cur.execute(
                "INSERT OR REPLACE INTO builds VALUES (?,?,?,?,?,?,?,?,?)",
                (dataset, state, done, total, error, os.getpid(), host_name(), started, now),
            )

    def clear_build_status(self, dataset: str) -> None:
        """Forget a dataset's build status."""
        with self._write() as cur:
            forget_build(cur, dataset)

    def build_statuses(self) -> dict[str, BuildStatus]:
        """Every recorded build; a 'building' entry whose process is gone is reported as failed."""
        out = {}
        for r in self._con().execute("SELECT * FROM builds"):
            status = BuildStatus(*r)
            if status.state == "building" and status.host == host_name() and not pid_alive(status.pid):
                status = BuildStatus(
                    status.dataset,
                    "failed",
                    status.done,
                    status.total,
                    "the build was interrupted",
                    status.pid,
                    status.host,
                    status.started,
                    status.updated,
                )
            out[status.dataset] = status
        return out
