"""A shard: a batch of a build's contour rows written where they were made, merged into the store by SQLite.

A task that makes a batch of store rows (``engine.build.datasets.batch_shard``) writes them into a small
SQLite database of the store's own tables, held in memory (:class:`Shard`), and merges it into the store
(:func:`merge_shard`): one ``INSERT ... SELECT`` per table run by SQLite itself, instead of unpickling every
row's arrays and inserting them one statement at a time.

Who merges: a worker that can open the store file (a local pool, a Dask cluster on one machine or on a shared
disk) merges its own shard (:func:`merge_on_worker`), so the build process only counts what came back; a
worker that cannot (another machine) sends the shard back and the build process merges it. Either way each
contour takes the fid reserved for its place in the build (:func:`engine.store.staging.reserve_fids`), so the
store holds the same rows under the same fids whoever merged them and in whatever order the batches landed.
"""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from engine.errors import BuildCancelled
from engine.store.builds import is_building
from engine.store.codec import RowTally, contour_pieces, contour_row
from engine.store.connection import StoreFile
from engine.store.issues import insert_issues
from engine.store.records import NewContour
from engine.store.schema import PIECE_KINDS, SCHEMA
from engine.store.staging import reservation

#: The dataset id rows carry inside a shard (the merge gives them the build's staged id).
SHARD_ID = "shard"
#: The name a shard is attached under on the store's connection while it is merged.
SHARD_SCHEMA = "shard"
#: Columns of the ``contours`` table copied as they are (all but fid and dataset).
_CONTOUR_VALUES = (
    "contour_id, elevation, closed, grp, vanish_scale, length_m, n_rows, n_input, t_at_scale, sim_t, sim, "
    "base, top, original, original_w, sig, sig_top, sig_original"
)
#: A shard is merged at most this many contours, or rows, per write transaction (then the next write of anyone
#: else may go): a batch of the sample's contours is merged in a few tens of milliseconds.
STAGE_CONTOURS = 64
STAGE_ROWS = 100_000


@dataclass(frozen=True)
class Shard:
    """A batch of contour rows as a serialized SQLite database (the store's tables), and their counts."""

    data: bytes
    tally: RowTally


@dataclass(frozen=True)
class MergedShard:
    """A shard that its worker merged into the store itself: only its counts come back."""

    tally: RowTally


@dataclass(frozen=True)
class StageTarget:
    """Where a build's rows go, as its tasks are told: the store file (an absolute path), the dataset and the
    row id its rows are staged under, the first fid reserved for them and the token the reservation carries.

    A worker that opens another file of that name (another machine's) finds another token or none, and
    merges nothing there."""

    path: str
    dataset: str
    stage: str
    first_fid: int
    token: str
    only_if_building: bool


def insert_contour(cur: sqlite3.Cursor, dataset: str, c: NewContour) -> int:
    """Insert one contour's row, R*Tree entry, pieces and issues under ``dataset``; its new fid."""
    cur.execute(
        "INSERT INTO contours(dataset, contour_id, elevation, closed, grp, vanish_scale, "
        "length_m, n_rows, n_input, base, top, original, original_w, t_at_scale, sim_t, sim, sig, "
        "sig_top, sig_original) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
        contour_row(dataset, c),
    )
    fid = int(cur.lastrowid or 0)
    cur.execute("INSERT INTO contour_rtree VALUES (?,?,?,?,?,?)", (fid, *c.box, dataset))
    if c.issues:
        insert_issues(cur, dataset, fid, c.issues)
    for kind, k, blobs, box in contour_pieces(c):
        marks = ",".join("?" * len(blobs))
        cur.execute(f"INSERT INTO {kind}_pieces VALUES (NULL,?,?,{marks})", (fid, k, *blobs))
        cur.execute(f"INSERT INTO {kind}_piece_rtree VALUES (?,?,?,?,?,?)", (cur.lastrowid, *box, dataset))
    return fid


def write_shard(rows: Iterable[NewContour]) -> Shard:
    """The rows written into a new in-memory database, serialized, with their counts."""
    con = sqlite3.connect(":memory:", isolation_level=None)
    try:
        con.executescript(SCHEMA)
        tally = RowTally()
        cur = con.cursor()
        cur.execute("BEGIN")
        for c in rows:
            insert_contour(cur, SHARD_ID, c)
            tally.add(c)
        cur.execute("COMMIT")
        return Shard(con.serialize(), tally)
    finally:
        con.close()


@contextmanager
def attached(con: sqlite3.Connection, shard: Shard) -> Iterator[list[tuple[int, int]]]:
    """The shard attached to ``con`` (outside any transaction) as :data:`SHARD_SCHEMA`; yields its contours'
    (fid, n_rows) in fid order, and detaches it afterwards."""
    con.execute(f"ATTACH DATABASE ':memory:' AS {SHARD_SCHEMA}")
    try:
        con.deserialize(shard.data, name=SHARD_SCHEMA)
        yield con.execute(f"SELECT fid, n_rows FROM {SHARD_SCHEMA}.contours ORDER BY fid").fetchall()
    finally:
        con.execute(f"DETACH DATABASE {SHARD_SCHEMA}")


def fid_runs(contours: list[tuple[int, int]], most_contours: int, most_rows: int) -> Iterator[tuple[int, int]]:
    """(first, last) fids of consecutive runs of an attached shard's contours, each at most ``most_contours``
    contours or about ``most_rows`` rows (a single contour may exceed it), so a merge holds the store's write
    lock for a bounded step."""
    start, rows = 0, 0
    for i, (_, n_rows) in enumerate(contours):
        rows += n_rows
        if i + 1 - start >= most_contours or rows >= most_rows or i + 1 == len(contours):
            yield contours[start][0], contours[i][0]
            start, rows = i + 1, 0


def merge_shard(store: StoreFile, target: StageTarget, shard: Shard, offset: int) -> bool:
    """Merge ``shard``, whose first contour is the build's ``offset``-th (from 0), into ``store`` under the
    target's staged id, a bounded run of contours per write transaction; False (nothing merged) when the store
    holds no reservation for the target with its token.

    Each run is one transaction that first checks the reservation (a build that failed, or was replaced, has
    dropped it) and the build (with ``only_if_building``), and skips a run already there, so a task run twice
    (a Dask worker lost after a run) merges each contour once.

    Raises
    ------
    BuildCancelled
        ``only_if_building`` and the dataset's build is no longer recorded (the dataset was deleted).
    """
    fid_base = target.first_fid + offset - 1  # the shard's fids count from 1
    with attached(store._con(), shard) as contours:
        for first, last in fid_runs(contours, STAGE_CONTOURS, STAGE_ROWS):
            with store._write() as cur:
                held = reservation(cur, target.stage)
                if held is None or held[2] != target.token:
                    return False
                if target.only_if_building and not is_building(cur, target.dataset):
                    raise BuildCancelled(f"dataset {target.dataset!r} was deleted while it built")
                if cur.execute("SELECT 1 FROM contours WHERE fid=?", (first + fid_base,)).fetchone() is None:
                    merge_run(cur, target.stage, first, last, fid_base)
    return True


#: The store files this process has opened to merge its shards into (a worker merges many), by path.
_OPENED: dict[str, StoreFile] = {}
#: How long a worker's merge waits for the store's write lock: every worker of a build takes it in turn, so
#: with many workers the wait is many merges long, not the few seconds a request of the service may wait.
MERGE_BUSY_TIMEOUT_S = 600.0


def merge_on_worker(target: StageTarget, shard: Shard, offset: int) -> Shard | MergedShard:
    """On a worker: ``shard`` merged into the target's store file when this process can open it and it holds
    the target's reservation (:class:`MergedShard`), else the shard itself, for the build process to merge."""
    for fresh in (False, True):  # a file kept open from an earlier build may have been replaced since
        store = None if fresh else _OPENED.get(target.path)
        if store is None:
            if not _holds_reservation(target):  # no file there, or another one: never create or touch it
                return shard
            store = _OPENED[target.path] = StoreFile(target.path, busy_timeout_s=MERGE_BUSY_TIMEOUT_S)
        if merge_shard(store, target, shard, offset):
            return MergedShard(shard.tally)
    return shard


def _holds_reservation(target: StageTarget) -> bool:
    """True when the file at the target's path is a store holding the target's reservation, read without
    writing (opening a store to write first makes its tables)."""
    if not os.path.isfile(target.path):
        return False
    try:
        con = sqlite3.connect(f"file:{target.path}?mode=ro", uri=True)
        try:
            held = reservation(con.cursor(), target.stage)
        finally:
            con.close()
    except sqlite3.DatabaseError:  # not a store (no store_meta), or not SQLite at all
        return False
    return held is not None and held[2] == target.token


def merge_run(cur: sqlite3.Cursor, dataset: str, first: int, last: int, fid_base: int) -> None:
    """Copy the attached shard's contours ``first``..``last`` (fids) into the store under ``dataset``, in one
    write transaction's cursor: fid ``f`` of the shard becomes ``f + fid_base``; the pieces take the next free
    piece ids, in the shard's order."""
    s = SHARD_SCHEMA
    cur.execute(
        f"INSERT INTO contours(fid, dataset, {_CONTOUR_VALUES}) SELECT fid + ?, ?, {_CONTOUR_VALUES} "
        f"FROM {s}.contours WHERE fid BETWEEN ? AND ? ORDER BY fid",
        (fid_base, dataset, first, last),
    )
    cur.execute(
        f"INSERT INTO contour_rtree SELECT fid + ?, minx, maxx, miny, maxy, ? FROM {s}.contour_rtree "
        "WHERE fid BETWEEN ? AND ? ORDER BY fid",
        (fid_base, dataset, first, last),
    )
    cur.execute(
        f"INSERT INTO contour_issues SELECT ?, fid + ?, step, reason FROM {s}.contour_issues "
        "WHERE fid BETWEEN ? AND ? ORDER BY rowid",
        (dataset, fid_base, first, last),
    )
    for kind, columns in PIECE_KINDS.items():
        names = ", ".join(columns)
        lo, hi = cur.execute(
            f"SELECT min(piece), max(piece) FROM {s}.{kind}_pieces WHERE fid BETWEEN ? AND ?", (first, last)
        ).fetchone()
        if lo is None:
            continue
        piece_base = _next_piece(cur, kind) - lo
        cur.execute(
            f"INSERT INTO {kind}_pieces(piece, fid, k, {names}) SELECT piece + ?, fid + ?, k, {names} "
            f"FROM {s}.{kind}_pieces WHERE piece BETWEEN ? AND ? ORDER BY piece",
            (piece_base, fid_base, lo, hi),
        )
        cur.execute(
            f"INSERT INTO {kind}_piece_rtree SELECT piece + ?, minx, maxx, miny, maxy, ? "
            f"FROM {s}.{kind}_piece_rtree WHERE piece BETWEEN ? AND ? ORDER BY piece",
            (piece_base, dataset, lo, hi),
        )


def _next_piece(cur: sqlite3.Cursor, kind: str) -> int:
    """The piece id SQLite would give the next row of pieces of ``kind``."""
    return int(cur.execute(f"SELECT coalesce(max(piece), 0) FROM main.{kind}_pieces").fetchone()[0]) + 1
