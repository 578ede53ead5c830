"""The contours a dataset version serves without some part of their build, and why (its build report).

One row per (contour, step) in the ``contour_issues`` table (engine/store/schema.py): written in the dataset's
write transaction, as its rows and labels are, and deleted with them. A store made before this table existed
gets it when first opened for writing; one opened read-only without it simply has no issues to tell.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable
from typing import Any

#: Issues a report lists at most (the total is always counted).
REPORTED_ISSUES = 1000

def insert_issues(cur: sqlite3.Cursor, dataset: str, fid: int, issues: Iterable[tuple[str, str]]) -> None:
    """Record (step, reason) of one stored contour."""
    cur.executemany(
        "INSERT INTO contour_issues VALUES (?,?,?,?)", [(dataset, int(fid), step, reason) for step, reason in issues]
    )


def read_issues(
    con: sqlite3.Connection, dataset: str, limit: int = REPORTED_ISSUES
) -> tuple[list[dict[str, Any]], int]:
    """The first ``limit`` issues of a dataset, in fid order, as JSON objects (``fid``, the source feature's
    ``id``, ``step``, ``reason``), and how many there are in all."""
    try:
        total = int(con.execute("SELECT COUNT(*) FROM contour_issues WHERE dataset=?", (dataset,)).fetchone()[0])
        rows = con.execute(
            "SELECT i.fid, c.contour_id, i.step, i.reason FROM contour_issues i LEFT JOIN contours c "
            "ON c.fid = i.fid WHERE i.dataset=? ORDER BY i.fid, i.rowid LIMIT ?",
            (dataset, int(limit)),
        ).fetchall()
    except sqlite3.OperationalError as exc:
        if "no such table" in str(exc):  # an older store opened read-only
            return [], 0
        raise
    return [{"fid": int(f), "id": cid, "step": step, "reason": reason} for f, cid, step, reason in rows], total
