"""Rows written out of sight: a build stages its rows under a private id, one short switch makes them the dataset.

A dataset's contour rows (their R*Tree entries, pieces and issues too) are stored under one of its two private
*row ids* (:func:`row_ids`), and its row in ``datasets`` names which (``rows_id``); every read of its rows goes
through that column. A build writes its rows in bounded transactions under the row id its dataset does not use
now (:func:`staging_id`), which no reader asks for. The switch (:meth:`engine.store.store.CCSStore.save`) only
points the dataset's row at them: no row is rewritten, so it takes the same few milliseconds whatever the
dataset's size (renaming a 16x terrain's 450 MB of rows had held the write lock for 3 s). The replaced
version's rows are then removed a few contours at a time (:func:`purge_some`). So no write waits on a build for
longer than one bounded step, and a build killed at any moment leaves the previous version as it was (its
staged rows are removed by the next build of that id or at the next start: :func:`leftover_ids`).

A row id replaces the first (one of them) or the last (the other) character of the dataset's id by a marker;
markers never occur in a dataset id (``[a-z0-9_-]``), so the two never meet each other or a real id. A store
of format 3 kept a dataset's rows under the dataset's own id: opened for writing it says so in ``rows_id``
(:mod:`engine.store.schema`), and the first rebuild moves it to a private row id like any other.
"""

from __future__ import annotations

import sqlite3

from engine.errors import StoreError
from engine.store.schema import PIECE_KINDS

#: The characters of a dataset id and, position for position, the markers that stand for them in private ids.
_ID_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_-"
_MARKERS = "".join(chr(c) for c in range(2, 32)) + "\x7f`{|}~^\\"
_MARK = dict(zip(_ID_CHARS, _MARKERS, strict=True))
#: Row ids of a dataset id outside ``[a-z0-9_-]`` (or of one character): a prefix and a tag.
_OTHER = "\x01"
_PRIVATE = frozenset(_MARKERS + _OTHER)

#: Contours removed per transaction by :func:`purge_some`.
PURGE_CONTOURS = 64
#: The ``store_meta`` key of a staged id's reservation of fids (:func:`reserve_fids`) is this and the id.
_RESERVED = "fids:"


def _marked(dataset: str, at: int, tag: str) -> str:
    if len(dataset) < 2 or any(c not in _MARK for c in dataset):
        return f"{_OTHER}{tag}{dataset}"
    chars = list(dataset)
    chars[at] = _MARK[chars[at]]
    return "".join(chars)


def row_ids(dataset: str) -> tuple[str, str]:
    """The two private ids a dataset's rows are stored under, one version after the other."""
    return _marked(dataset, 0, "s"), _marked(dataset, -1, "r")


def staging_id(dataset: str, live: str | None) -> str:
    """The row id a build of ``dataset`` writes under: the one of its two that its version ``live`` (its
    current row id, None when it has none) does not use."""
    first, second = row_ids(dataset)
    return second if live == first else first


def is_private(ident: str) -> bool:
    """True for a row id (never a dataset's)."""
    return any(c in _PRIVATE for c in ident)


def live_row_ids(cur: sqlite3.Cursor | sqlite3.Connection) -> set[str]:
    """The row ids the stored datasets read (a staged dataset row, of private id, reads none yet)."""
    return {rows for ident, rows in cur.execute("SELECT id, rows_id FROM datasets") if not is_private(ident)}


def purge_some(cur: sqlite3.Cursor, ident: str, limit: int = PURGE_CONTOURS) -> int:
    """Remove up to ``limit`` contours of row id ``ident`` with their pieces; when none is left, its issue rows
    too, and the dataset and label rows of a private id (a staged build's). The number of contours removed (0:
    nothing of ``ident`` is left). The rows a stored dataset reads are never removed.

    Raises
    ------
    StoreError
        ``ident`` holds a stored dataset's rows.
    """
    if ident in live_row_ids(cur):
        raise StoreError(f"the rows {ident!r} are a stored dataset's: not removed")
    fids = [r[0] for r in cur.execute("SELECT fid FROM contours WHERE dataset=? LIMIT ?", (ident, int(limit)))]
    if not fids:
        drop_reservation(cur, ident)
        cur.execute("DELETE FROM contour_issues WHERE dataset=?", (ident,))
        if is_private(ident):
            cur.execute("DELETE FROM labels WHERE dataset=?", (ident,))
            cur.execute("DELETE FROM datasets WHERE id=?", (ident,))
        return 0
    marks = ",".join("?" * len(fids))
    for kind in PIECE_KINDS:
        pieces = f"SELECT piece FROM {kind}_pieces WHERE fid IN ({marks})"
        cur.execute(f"DELETE FROM {kind}_piece_rtree WHERE piece IN ({pieces})", fids)
        cur.execute(f"DELETE FROM {kind}_pieces WHERE fid IN ({marks})", fids)
    cur.execute(f"DELETE FROM contour_rtree WHERE fid IN ({marks})", fids)
    cur.execute(f"DELETE FROM contour_issues WHERE dataset=? AND fid IN ({marks})", (ident, *fids))
    cur.execute(f"DELETE FROM contours WHERE fid IN ({marks})", fids)
    return len(fids)


def leftover_ids(con: sqlite3.Connection) -> list[str]:
    """The ids that hold rows no stored dataset reads (of builds killed or stopped, of versions not yet
    removed), sorted."""
    rows = {r[0] for r in con.execute("SELECT DISTINCT dataset FROM contours")}
    staged = {r[0] for r in con.execute("SELECT id FROM datasets") if is_private(r[0])}
    reserved = {
        r[0][len(_RESERVED) :] for r in con.execute("SELECT key FROM store_meta WHERE key >= ? AND key < ?", _PREFIX)
    }
    return sorted((rows | staged | reserved) - live_row_ids(con))


#: The range of ``store_meta`` keys that are reservations.
_PREFIX = (_RESERVED, _RESERVED[:-1] + chr(ord(_RESERVED[-1]) + 1))


def reserve_fids(cur: sqlite3.Cursor, ident: str, count: int, token: str) -> int:
    """Set aside the next ``count`` fids for the rows staged under ``ident``, in a write transaction's cursor,
    and record them with ``token``; the first of them.

    So the rows of a build get the same fids whoever writes them and in whatever order its batches land (a
    worker writes its own batch at its place), and no other write takes them meanwhile: AUTOINCREMENT gives
    fids past the highest ``sqlite_sequence`` has seen, which now counts the reserved ones."""
    top = int(cur.execute("SELECT coalesce(max(fid), 0) FROM contours").fetchone()[0])
    row = cur.execute("SELECT seq FROM sqlite_sequence WHERE name='contours'").fetchone()
    first = max(top, int(row[0]) if row else 0) + 1
    last = first + int(count) - 1
    if row is None:
        cur.execute("INSERT INTO sqlite_sequence(name, seq) VALUES ('contours', ?)", (last,))
    else:
        cur.execute("UPDATE sqlite_sequence SET seq=? WHERE name='contours'", (last,))
    cur.execute(
        "INSERT OR REPLACE INTO store_meta VALUES (?, ?)", (_RESERVED + ident, f"{first} {int(count)} {token}")
    )
    return first


def reservation(cur: sqlite3.Cursor, ident: str) -> tuple[int, int, str] | None:
    """(first fid, count, token) reserved for the rows staged under ``ident``, or None."""
    row = cur.execute("SELECT value FROM store_meta WHERE key=?", (_RESERVED + ident,)).fetchone()
    if row is None:
        return None
    first, count, token = str(row[0]).split(" ", 2)
    return int(first), int(count), token


def drop_reservation(cur: sqlite3.Cursor, ident: str) -> None:
    """Forget the fids reserved for ``ident`` (its rows switched in or removed): a worker still running for that
    build then finds no reservation and writes nothing."""
    cur.execute("DELETE FROM store_meta WHERE key=?", (_RESERVED + ident,))


def owner_of(ident: str) -> str | None:
    """The dataset id a row id stands for (None for a dataset's own id)."""
    if ident.startswith(_OTHER):
        return ident[2:]
    if ident[0] in _PRIVATE:
        return _ID_CHARS[_MARKERS.index(ident[0])] + ident[1:]
    if ident[-1] in _PRIVATE:
        return ident[:-1] + _ID_CHARS[_MARKERS.index(ident[-1])]
    return None
