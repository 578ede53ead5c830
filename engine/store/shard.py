"""A shard: a batch of a build's contour rows written where they were made, merged into the store by SQLite.

A worker that makes a batch of store rows (``engine.build.datasets.batch_shard``) writes them into a small
SQLite database of the store's own tables, held in memory, and returns that database's bytes
(:class:`Shard`). The build process then only merges each shard into the store (:func:`attached`,
:func:`merge_run`): one
``INSERT ... SELECT`` per table run by SQLite itself, instead of unpickling every row's arrays and inserting
them one statement at a time. The fids and piece ids a merge gives are the ones a row-by-row insert gives (the
next free ones, in the shard's order), so the store holds the same rows under the same ids whichever way they
were written.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from engine.store.codec import RowTally, contour_pieces, contour_row
from engine.store.issues import insert_issues
from engine.store.records import NewContour
from engine.store.schema import PIECE_KINDS, SCHEMA

#: The dataset id rows carry inside a shard (the merge gives them the build's staged id).
SHARD_ID = "shard"
#: The name a shard is attached under on the store's connection while it is merged.
SHARD_SCHEMA = "shard"
#: Columns of the ``contours`` table copied as they are (all but fid and dataset).
_CONTOUR_VALUES = (
    "contour_id, elevation, closed, grp, vanish_scale, length_m, n_rows, n_input, t_at_scale, sim_t, sim, "
    "base, top, original, original_w, sig, sig_top, sig_original"
)


@dataclass(frozen=True)
class Shard:
    """A batch of contour rows as a serialized SQLite database (the store's tables), and their counts."""

    data: bytes
    tally: RowTally


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


def merge_run(cur: sqlite3.Cursor, dataset: str, first: int, last: int) -> None:
    """Copy the attached shard's contours ``first``..``last`` (fids) into the store under ``dataset``, in one
    write transaction's cursor: the next free fids and piece ids, in the shard's order."""
    s = SHARD_SCHEMA
    fid_base = _next_id(cur, "contours", "fid", autoincrement=True) - first
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
        piece_base = _next_id(cur, f"{kind}_pieces", "piece", autoincrement=False) - lo
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


def _next_id(cur: sqlite3.Cursor, table: str, column: str, *, autoincrement: bool) -> int:
    """The id SQLite would give the next row of ``table`` (AUTOINCREMENT: past every id ever used)."""
    top = int(cur.execute(f"SELECT coalesce(max({column}), 0) FROM main.{table}").fetchone()[0])
    if autoincrement:
        row = cur.execute("SELECT seq FROM main.sqlite_sequence WHERE name=?", (table,)).fetchone()
        top = max(top, int(row[0]) if row else 0)
    return top + 1
