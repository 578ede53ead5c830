"""Rows written out of sight: a build stages its rows under a private id, one short switch makes them the dataset.

A build's rows go in bounded transactions under the dataset's *staged* id (:func:`staged_id`), which no reader
asks for; the last transaction (:meth:`engine.store.store.CCSStore.save`) moves the old version's rows to the
*retired* id (:func:`retired_id`), the staged rows to the dataset's id and writes its row, and the retired rows
are then removed a few contours at a time (:func:`purge_some`). So no write waits on a build for longer than
one bounded step, and a build killed at any moment leaves the previous version as it was (its staged rows are
removed by the next build of that id or at the next start: :func:`leftover_ids`).

A private id has the byte length of the dataset's id: a row renamed keeps its size, so SQLite overwrites its
first page in place instead of copying its blobs (a 450 MB rename costs 0.5 s instead of 4 s and 450 MB of
write-ahead log). The staged id replaces the first character by a marker, the retired id the last; markers
never occur in a dataset id (``[a-z0-9_-]``), so the two never meet each other or a real id.
"""

from __future__ import annotations

import sqlite3

from engine.store.schema import PIECE_KINDS

#: The characters of a dataset id and, position for position, the markers that stand for them in private ids.
_ID_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_-"
_MARKERS = "".join(chr(c) for c in range(2, 32)) + "\x7f`{|}~^\\"
_MARK = dict(zip(_ID_CHARS, _MARKERS, strict=True))
#: Private ids of a dataset id outside ``[a-z0-9_-]`` (or of one character): a prefix (renaming rewrites rows).
_OTHER = "\x01"
_PRIVATE = frozenset(_MARKERS + _OTHER)

#: Contours removed per transaction by :func:`purge_some`.
PURGE_CONTOURS = 64


def _marked(dataset: str, at: int, tag: str) -> str:
    if len(dataset) < 2 or any(c not in _MARK for c in dataset):
        return f"{_OTHER}{tag}{dataset}"
    chars = list(dataset)
    chars[at] = _MARK[chars[at]]
    return "".join(chars)


def staged_id(dataset: str) -> str:
    """The id a build of ``dataset`` writes its rows under until the switch."""
    return _marked(dataset, 0, "s")


def retired_id(dataset: str) -> str:
    """The id the replaced (or deleted) version's rows wait under to be removed."""
    return _marked(dataset, -1, "r")


def is_private(ident: str) -> bool:
    """True for a staged or retired id (never a dataset's)."""
    return any(c in _PRIVATE for c in ident)


def rename_rows(cur: sqlite3.Cursor, old: str, new: str) -> None:
    """Give the contour rows (their R*Tree entries, pieces and issues) of id ``old`` the id ``new``."""
    fids = "SELECT fid FROM contours WHERE dataset=?"
    cur.execute(f"UPDATE contour_rtree SET dataset=? WHERE fid IN ({fids})", (new, old))
    for kind in PIECE_KINDS:
        pieces = f"SELECT piece FROM {kind}_pieces WHERE fid IN ({fids})"
        cur.execute(f"UPDATE {kind}_piece_rtree SET dataset=? WHERE piece IN ({pieces})", (new, old))
    cur.execute("UPDATE contour_issues SET dataset=? WHERE dataset=?", (new, old))
    cur.execute("UPDATE contours SET dataset=? WHERE dataset=?", (new, old))


def purge_some(cur: sqlite3.Cursor, ident: str, limit: int = PURGE_CONTOURS) -> int:
    """Remove up to ``limit`` contours of id ``ident`` with their pieces; when none is left, its dataset, label
    and issue rows too. The number of contours removed (0: nothing of ``ident`` is left)."""
    fids = [r[0] for r in cur.execute("SELECT fid FROM contours WHERE dataset=? LIMIT ?", (ident, int(limit)))]
    if not fids:
        cur.execute("DELETE FROM contour_issues WHERE dataset=?", (ident,))
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
    """The private ids that hold rows (of builds killed or stopped, of versions not yet removed)."""
    rows = con.execute("SELECT DISTINCT dataset FROM contours UNION SELECT id FROM datasets").fetchall()
    return [r[0] for r in rows if is_private(r[0])]


def owner_of(ident: str) -> str | None:
    """The dataset id a staged id stands for (None for a retired id)."""
    if ident.startswith(_OTHER):
        return ident[2:] if ident[1:2] == "s" else None
    if ident[0] in _PRIVATE:
        return _ID_CHARS[_MARKERS.index(ident[0])] + ident[1:]
    return None
