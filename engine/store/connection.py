"""One store file opened: a SQLite connection per thread, write transactions, the write-ahead log, checks.

- One file, stdlib ``sqlite3``, WAL mode: several processes read it at once while one writes.
- A write runs in one ``BEGIN IMMEDIATE`` transaction; a write the file system refuses (full disk, read-only
  file) is rolled back and raised as :class:`~engine.errors.StoreUnwritable`.
- Every write transaction is short (a build writes in bounded steps, :mod:`engine.store.staging`), so a write
  waits at most :data:`BUSY_TIMEOUT_S` for another; past that it is raised as :class:`~engine.errors.StoreBusy`
  (nothing written), never as SQLite's "database is locked".

What is read and written is :class:`engine.store.builds.BuildBook`'s and :class:`engine.store.store.CCSStore`'s.
"""

from __future__ import annotations

import errno
import os
import sqlite3
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from engine.errors import StoreBusy, StoreError, StoreFormatError, StoreUnwritable
from engine.store.schema import MIGRATIONS, SCHEMA, STORE_FORMAT

#: SQLite's messages for a write the file system refuses (full disk, read-only mount or file, I/O error).
_UNWRITABLE_MESSAGES = ("database or disk is full", "readonly database", "disk i/o error", "unable to open")
#: SQLite's messages for a write that found the store locked by another for longer than it waits.
_BUSY_MESSAGES = ("database is locked", "database is busy", "database table is locked")
#: Seconds a write waits for another process's write transaction (each is short: a bounded step of a build).
BUSY_TIMEOUT_S = 5.0


def unwritable_reason(exc: BaseException) -> str | None:
    """Why a write failed when the file system refused it (else None: a bug, not the disk)."""
    text = str(exc).lower()
    if isinstance(exc, sqlite3.OperationalError) and any(m in text for m in _UNWRITABLE_MESSAGES):
        return str(exc)
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EDQUOT, errno.EPERM):
        return os.strerror(exc.errno or 0)
    return None


def is_busy(exc: BaseException) -> bool:
    """Whether SQLite gave up waiting for another connection's lock."""
    return isinstance(exc, sqlite3.OperationalError) and any(m in str(exc).lower() for m in _BUSY_MESSAGES)


def create_schema(con: sqlite3.Connection) -> None:
    """Create the tables a new file lacks and, in a new file, its format and version counter."""
    con.executescript(SCHEMA)
    row = con.execute("SELECT value FROM store_meta WHERE key='format'").fetchone()
    if row is None:
        con.execute("INSERT OR IGNORE INTO store_meta VALUES ('format', ?)", (str(STORE_FORMAT),))
        con.execute("INSERT OR IGNORE INTO store_meta VALUES ('version_counter', '0')")
        con.commit()


def migrate(con: sqlite3.Connection) -> None:
    """Bring a store of an older format to this one (:data:`~engine.store.schema.MIGRATIONS`), in one write
    transaction; another process that migrated it first leaves nothing to do."""
    con.execute("BEGIN IMMEDIATE")
    try:
        found = stored_format(con)
        while found is not None and found in MIGRATIONS:
            for statement in MIGRATIONS[found]:
                con.execute(statement)
            found = stored_format(con)
        con.execute("COMMIT")
    except BaseException:
        con.execute("ROLLBACK")
        raise


def stored_format(con: sqlite3.Connection) -> int | None:
    """The format the file says it has (None: not a ccsm store)."""
    row = con.execute("SELECT value FROM store_meta WHERE key='format'").fetchone()
    return None if row is None else int(row[0])


class StoreFile:
    """One SQLite store file. Thread-safe: each thread gets its own connection.

    Parameters
    ----------
    path
        The file; created (with its directory) if missing.
    readonly
        Open without creating or migrating (for a second process that only reads).
    mmap_bytes
        Read up to this much of the file through memory mapping (SQLite's ``mmap_size``; 0: SQLite's default,
        none). A serving process reads the stored pieces of a large dataset this way without copying each
        page into its own cache: the mapped pages are the system's shared file cache, not the process's memory.
    busy_timeout_s
        How long a write waits for another's lock before :class:`~engine.errors.StoreBusy` (None:
        :data:`BUSY_TIMEOUT_S`).

    Raises
    ------
    StoreError
        The file is not a ccsm store, is of another format, or cannot be opened.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        readonly: bool = False,
        mmap_bytes: int = 0,
        busy_timeout_s: float | None = None,
    ) -> None:
        self.path = Path(path)
        self.readonly = readonly
        self.mmap_bytes = int(mmap_bytes)
        self.busy_timeout_s = BUSY_TIMEOUT_S if busy_timeout_s is None else float(busy_timeout_s)
        self._local = threading.local()
        if not readonly:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        elif not self.path.exists():
            raise StoreError(f"store {self.path.name} does not exist")
        try:
            con = self._con()
            if not readonly:
                create_schema(con)
                migrate(con)
            found = stored_format(con)
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"store {self.path.name} cannot be opened: {exc}") from exc
        if found != STORE_FORMAT:
            raise StoreFormatError(
                f"store {self.path.name} has format {'unknown' if found is None else found}, expected {STORE_FORMAT}"
            )

    def _con(self) -> sqlite3.Connection:
        con: sqlite3.Connection | None = getattr(self._local, "con", None)
        if con is None:
            uri = f"file:{self.path}?mode={'ro' if self.readonly else 'rwc'}"
            con = sqlite3.connect(
                uri, uri=True, timeout=self.busy_timeout_s, isolation_level=None, check_same_thread=False
            )
            if not self.readonly:
                con.execute("PRAGMA journal_mode=WAL")
            # NORMAL is durable for WAL across application crashes (kill -9); only a power cut may lose the
            # last commit, never corrupt the file.
            con.execute("PRAGMA synchronous=NORMAL")
            con.execute(f"PRAGMA busy_timeout={int(self.busy_timeout_s * 1000)}")
            if self.mmap_bytes:
                con.execute(f"PRAGMA mmap_size={self.mmap_bytes}")
            self._local.con = con
        return con

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Cursor]:
        """One write transaction (BEGIN IMMEDIATE ... COMMIT, ROLLBACK on any exception)."""
        con = self._con()
        cur = con.cursor()
        try:
            cur.execute("BEGIN IMMEDIATE")
            try:
                yield cur
            except BaseException:
                if con.in_transaction:
                    con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            if is_busy(exc):
                if con.in_transaction:
                    con.execute("ROLLBACK")
                raise StoreBusy(f"store {self.path.name} is busy with another write; try again shortly") from exc
            reason = unwritable_reason(exc)
            if reason is None:
                raise
            if con.in_transaction:
                con.execute("ROLLBACK")
            self._shrink_wal()  # a full disk must not stay full of a rolled-back transaction's WAL
            raise StoreUnwritable(f"store {self.path.name} cannot be written: {reason}") from exc

    def _shrink_wal(self) -> None:
        try:
            self._con().execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except sqlite3.DatabaseError:
            pass  # best effort: the next start checkpoints again

    def checkpoint(self) -> None:
        """Copy the WAL into the file and truncate it (at start: a WAL left by a crash or a full disk)."""
        if not self.readonly:
            self._shrink_wal()

    def quick_check(self) -> str:
        """``ok``, or what SQLite's ``PRAGMA quick_check`` found wrong with the file (first lines)."""
        try:
            rows = [str(r[0]) for r in self._con().execute("PRAGMA quick_check(5)")]
        except sqlite3.DatabaseError as exc:
            return str(exc)
        return "ok" if rows == ["ok"] else "; ".join(rows)

    def integrity_ok(self) -> bool:
        """SQLite's own integrity check of the file."""
        return self._con().execute("PRAGMA integrity_check").fetchone()[0] == "ok"

    def probe_write(self) -> None:
        """A real (tiny) write transaction: raises StoreUnwritable when the store cannot be written now."""
        with self._write() as cur:
            cur.execute("UPDATE store_meta SET value=value WHERE key='format'")

    def close(self) -> None:
        """Close this thread's connection."""
        con = getattr(self._local, "con", None)
        if con is not None:
            con.close()
            self._local.con = None
