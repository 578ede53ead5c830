"""The store: precomputed CCS rows, Sim(t) and t(scale) tables and dataset metadata in one SQLite file.

Persistence only: the rows arrive ready (reprojected, with their significance; :mod:`engine.serve.records`)
and leave decoded; what they mean is the serving layer's business.

- One file, stdlib ``sqlite3``, WAL mode: several processes read it at once while one writes.
- Contour extents sit in an R*Tree (EPSG:3857), so a tile looks up only the contours it touches.
- A dataset is written in **one transaction** (old rows out, new rows in, new ``data_version``): a build
  killed at any moment leaves the previous content as it was; SQLite's journal undoes the partial write.
- Each dataset records the content hash of its source and build parameters, so a changed source is rebuilt
  and an unchanged one is served at once after a restart.
"""

from __future__ import annotations

import errno
import json
import math
import os
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.errors import BuildCancelled, StoreError, StoreFormatError, StoreUnwritable, UnknownLayer
from engine.scratch import host_name, pid_alive
from engine.store.issues import ISSUES_SCHEMA, delete_issues, insert_issues, read_issues
from engine.types import Coords

#: Bumped whenever the layout of the file changes; a store of another format is refused.
STORE_FORMAT = 3
#: Rows of a stored piece of a contour's rows (piece k holds rows k * PIECE_ROWS to (k + 1) * PIECE_ROWS, both
#: included): a tile of a dataset too large to hold in memory reads only the pieces it meets. A multiple of the
#: tiles' chunk rows (engine.serve.pieces checks it), so a piece's chunks are the whole line's.
PIECE_ROWS = 256

_SCHEMA = """
CREATE TABLE IF NOT EXISTS store_meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS datasets(
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    source TEXT NOT NULL,
    source_hash TEXT NOT NULL,
    params TEXT NOT NULL,
    data_version INTEGER NOT NULL,
    built_at REAL NOT NULL,
    build_seconds REAL NOT NULL,
    working_crs TEXT NOT NULL,
    source_crs TEXT NOT NULL,
    interval REAL,
    minx REAL, miny REAL, maxx REAL, maxy REAL,
    n_contours INTEGER NOT NULL,
    n_closed INTEGER NOT NULL,
    n_vertices INTEGER NOT NULL,
    source_scale REAL NOT NULL,
    target_scale REAL NOT NULL,
    ladder BLOB NOT NULL,
    bad_features TEXT NOT NULL
);
-- The small per-contour columns come before the rows: reading them (a tile's contour heads) does not walk
-- the rows' overflow pages.
CREATE TABLE IF NOT EXISTS contours(
    fid INTEGER PRIMARY KEY AUTOINCREMENT,
    dataset TEXT NOT NULL,
    contour_id TEXT NOT NULL,
    elevation REAL NOT NULL,
    closed INTEGER NOT NULL,
    grp INTEGER NOT NULL,
    vanish_scale REAL,
    length_m REAL NOT NULL,
    n_rows INTEGER NOT NULL,
    n_input INTEGER NOT NULL,
    t_at_scale BLOB NOT NULL,
    sim_t BLOB NOT NULL,
    sim BLOB NOT NULL,
    base BLOB NOT NULL,
    top BLOB NOT NULL,
    original BLOB NOT NULL,
    original_w BLOB NOT NULL,
    sig BLOB NOT NULL,
    sig_top BLOB NOT NULL,
    sig_original BLOB NOT NULL
);
CREATE INDEX IF NOT EXISTS contours_dataset ON contours(dataset);
CREATE TABLE IF NOT EXISTS ccs_pieces(
    piece INTEGER PRIMARY KEY,
    fid INTEGER NOT NULL,
    k INTEGER NOT NULL,
    base BLOB NOT NULL,
    top BLOB NOT NULL,
    sig BLOB NOT NULL,
    sig_top BLOB NOT NULL
);
CREATE INDEX IF NOT EXISTS ccs_pieces_fid ON ccs_pieces(fid);
CREATE VIRTUAL TABLE IF NOT EXISTS ccs_piece_rtree USING rtree(piece, minx, maxx, miny, maxy, +dataset TEXT);
CREATE TABLE IF NOT EXISTS original_pieces(
    piece INTEGER PRIMARY KEY,
    fid INTEGER NOT NULL,
    k INTEGER NOT NULL,
    original BLOB NOT NULL,
    sig_original BLOB NOT NULL
);
CREATE INDEX IF NOT EXISTS original_pieces_fid ON original_pieces(fid);
CREATE VIRTUAL TABLE IF NOT EXISTS original_piece_rtree USING rtree(piece, minx, maxx, miny, maxy, +dataset TEXT);
CREATE TABLE IF NOT EXISTS labels(
    dataset TEXT PRIMARY KEY,
    data_version INTEGER NOT NULL,
    last_zoom REAL NOT NULL,
    n INTEGER NOT NULL,
    xy BLOB NOT NULL,
    angle BLOB NOT NULL,
    min_zoom BLOB NOT NULL,
    fid BLOB NOT NULL,
    rank BLOB NOT NULL,
    elevation BLOB NOT NULL,
    text TEXT NOT NULL,
    box_px BLOB NOT NULL
);
CREATE VIRTUAL TABLE IF NOT EXISTS contour_rtree USING rtree(fid, minx, maxx, miny, maxy, +dataset TEXT);
CREATE TABLE IF NOT EXISTS builds(
    dataset TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    done INTEGER NOT NULL,
    total INTEGER NOT NULL,
    error TEXT,
    pid INTEGER NOT NULL,
    host TEXT NOT NULL,
    started REAL NOT NULL,
    updated REAL NOT NULL
);
"""


@dataclass(frozen=True)
class DatasetInfo:
    """A stored dataset's metadata.

    Attributes
    ----------
    bounds_3857
        (minx, miny, maxx, maxy) of every contour's CCS, EPSG:3857 metres.
    ladder
        (S,) scale denominators at which each contour's t is tabulated.
    data_version
        Increases with every write of the dataset; tiles are deterministic given it.
    """

    id: str
    name: str
    source: str
    source_hash: str
    params: dict[str, Any]
    data_version: int
    built_at: float
    build_seconds: float
    working_crs: str
    source_crs: str
    interval: float | None
    bounds_3857: tuple[float, float, float, float]
    n_contours: int
    n_closed: int
    n_vertices: int
    source_scale: float
    target_scale: float
    ladder: NDArray[np.float64]
    bad_features: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True)
class ContourRecord:
    """One stored contour, decoded: every array a tile or /simplify needs.

    Attributes
    ----------
    fid
        Stable integer id of the row (MVT feature id).
    base, top
        (M, 2) CCS rows in EPSG:3857 metres (a ring as a closed path).
    original
        (n, 2) input contour in EPSG:3857 (a ring as a closed path).
    original_w
        (n, 2) input contour in the working CRS, metres (a ring *without* its repeated vertex).
    t_at_scale
        (S,) t at each scale of the dataset's ladder.
    sim_t, sim
        The Sim(t) table.
    sig, sig_top, sig_original
        (M,), (M,) and (n,) float32 significance of each row of base/top together, of top alone (for a contour
        drawn at t = 1) and of the original, EPSG:3857 metres (:mod:`engine.tiles.significance`): a tile whose
        grid unit is u skips rows below u / 2.
    """

    fid: int
    dataset: str
    contour_id: str
    elevation: float
    closed: bool
    group: int
    vanish_scale: float
    length_m: float
    base: Coords
    top: Coords
    original: Coords
    original_w: Coords
    t_at_scale: NDArray[np.float64]
    sim_t: NDArray[np.float64]
    sim: NDArray[np.float64]
    sig: NDArray[np.float32]
    sig_top: NDArray[np.float32]
    sig_original: NDArray[np.float32]

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        return int(self.base.nbytes + self.top.nbytes + self.original.nbytes + self.original_w.nbytes)


@dataclass(frozen=True)
class ContourHead:
    """The per-contour columns of a stored contour without its rows (see :class:`ContourRecord`)."""

    fid: int
    elevation: float
    vanish_scale: float
    t_at_scale: NDArray[np.float64]


#: The kinds of stored pieces: of the CCS rows (columns base, top, sig, sig_top) and of the original (columns
#: original, sig_original).
PIECE_KINDS = {"ccs": ("base", "top", "sig", "sig_top"), "original": ("original", "sig_original")}


@dataclass(frozen=True)
class StoredPieces:
    """Pieces of one kind of some contours' rows, concatenated: piece ``i`` is piece ``k[i]`` of contour
    ``fid[i]`` and holds ``n[i]`` rows of each column (:data:`PIECE_KINDS`); piece k holds rows
    ``k * PIECE_ROWS`` to ``(k + 1) * PIECE_ROWS`` of its contour, both included (consecutive pieces share a row).
    """

    fid: NDArray[np.int64]
    k: NDArray[np.int64]
    n: NDArray[np.int64]
    columns: tuple[NDArray[Any], ...]


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


@dataclass(frozen=True)
class NewContour:
    """One contour row to write: what :class:`ContourRecord` reads back, plus its R*Tree box.

    ``box`` is (minx, maxx, miny, maxy) in EPSG:3857 of every row the contour can draw; ``n_input`` is the
    number of input vertices.
    """

    contour_id: str
    elevation: float
    closed: bool
    group: int
    vanish_scale: float
    length_m: float
    n_input: int
    base: Coords
    top: Coords
    original: Coords
    original_w: Coords
    t_at_scale: NDArray[np.float64]
    sim_t: NDArray[np.float64]
    sim: NDArray[np.float64]
    sig: NDArray[np.float32]
    sig_top: NDArray[np.float32]
    sig_original: NDArray[np.float32]
    box: tuple[float, float, float, float]
    #: (step, reason) of each per-contour step the build could not finish (the contour is served without it).
    issues: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class StoredLabels:
    """A dataset version's label anchors as stored (the arrays of
    :class:`engine.cartography.labels.LabelAnchors`), placed for zooms up to ``last_zoom``.

    Written with the contour rows (their fids are only known inside the write transaction), so a tile never
    places labels itself.
    """

    data_version: int
    last_zoom: float
    xy: NDArray[np.float64]
    angle: NDArray[np.float64]
    min_zoom: NDArray[np.float64]
    fid: NDArray[np.int64]
    rank: NDArray[np.int64]
    elevation: NDArray[np.float64]
    text: list[str]
    box_px: NDArray[np.float64]
    #: (fid, reason) of each contour whose label could not be placed (it is served without one).
    issues: tuple[tuple[int, str], ...] = ()


#: Places a dataset's labels once its rows and metadata are written: called inside the write transaction on
#: the writing thread, whose reads (``dataset``, ``load``, ...) see the new version before it is committed.
LabelPlacer = Callable[[], StoredLabels]


@dataclass(frozen=True)
class NewDataset:
    """A dataset's metadata to write beside its contour rows."""

    name: str
    source: str
    source_hash: str
    params: dict[str, Any]
    build_seconds: float
    working_crs: str
    source_crs: str
    interval: float | None
    source_scale: float
    target_scale: float
    ladder: NDArray[np.float64]
    bad_features: list[dict[str, Any]]


def _blob(a: NDArray[np.float64]) -> bytes:
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


def _array(b: bytes, cols: int = 0) -> NDArray[np.float64]:
    a = np.frombuffer(b, dtype="<f8")
    return a.reshape(-1, cols) if cols else a


def pieces_sql(kind: str, by_fid: bool) -> str:
    """The query of :meth:`CCSStore.pieces_meeting`: pieces of ``kind`` whose box meets (minx, maxx, miny, maxy),
    of one dataset (its id; ``by_fid``: its first and last fid).

    The R*Tree is searched first: ``+p.fid`` keeps SQLite from walking the pieces' fid index over the whole
    dataset instead (a hundred times slower at 64× the sample)."""
    columns = ", ".join(f"p.{c}" for c in PIECE_KINDS[kind])
    ours = "+p.fid BETWEEN ? AND ?" if by_fid else "r.dataset = ?"
    return (
        f"SELECT p.fid, p.k, {columns} FROM {kind}_piece_rtree r JOIN {kind}_pieces p ON p.piece = r.piece "
        f"WHERE r.maxx >= ? AND r.minx <= ? AND r.maxy >= ? AND r.miny <= ? AND {ours}"
    )


def _column(name: str, blob: bytes) -> NDArray[Any]:
    """A stored piece's column: float32 significance, else (n, 2) float64 rows."""
    return np.frombuffer(blob, dtype="<f4") if name.startswith("sig") else _array(blob, 2)


def _contour_row(dataset: str, c: NewContour) -> tuple[Any, ...]:
    return (
        dataset,
        str(c.contour_id),
        float(c.elevation),
        int(c.closed),
        int(c.group),
        None if math.isinf(c.vanish_scale) else float(c.vanish_scale),
        float(c.length_m),
        len(c.base),
        int(c.n_input),
        _blob(c.base),
        _blob(c.top),
        _blob(c.original),
        _blob(c.original_w),
        _blob(c.t_at_scale),
        _blob(c.sim_t),
        _blob(c.sim),
        np.asarray(c.sig, dtype="<f4").tobytes(),
        np.asarray(c.sig_top, dtype="<f4").tobytes(),
        np.asarray(c.sig_original, dtype="<f4").tobytes(),
    )


def piece_rows(n: int, k: int) -> slice:
    """The rows of piece ``k`` of ``n`` rows (empty beyond the last piece)."""
    lo = k * PIECE_ROWS
    if k and lo >= n - 1:
        return slice(0, 0)
    return slice(lo, min(lo + PIECE_ROWS, n - 1) + 1)


def piece_count(n: int) -> int:
    """Pieces of ``n`` rows (one at least)."""
    return max(1, -(-(n - 1) // PIECE_ROWS))


def _pieces(c: NewContour) -> Iterator[tuple[str, int, list[bytes], tuple[float, float, float, float]]]:
    """The stored pieces of a contour: kind, k, the columns' bytes, and the box (minx, maxx, miny, maxy) of its
    rows."""
    f4 = "<f4"
    for k in range(piece_count(len(c.base))):
        s = piece_rows(len(c.base), k)
        xy = np.concatenate([c.base[s], c.top[s]])
        sig = [np.asarray(c.sig[s], dtype=f4).tobytes(), np.asarray(c.sig_top[s], dtype=f4).tobytes()]
        yield "ccs", k, [_blob(c.base[s]), _blob(c.top[s]), *sig], _box(xy)
    for k in range(piece_count(len(c.original))):
        s = piece_rows(len(c.original), k)
        sig_original = np.asarray(c.sig_original[s], dtype=f4).tobytes()
        yield "original", k, [_blob(c.original[s]), sig_original], _box(c.original[s])


def _box(xy: NDArray[np.float64]) -> tuple[float, float, float, float]:
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


#: SQLite's messages for a write the file system refuses (full disk, read-only mount or file, I/O error).
_UNWRITABLE_MESSAGES = ("database or disk is full", "readonly database", "disk i/o error", "unable to open")


class _RowTally:
    """Counts and bounds of the rows written so far (a dataset's row is written after its contours)."""

    def __init__(self) -> None:
        self.n = 0
        self.closed = 0
        self.vertices = 0
        self.box = [math.inf, math.inf, -math.inf, -math.inf]  # minx, miny, maxx, maxy

    def add(self, c: NewContour) -> None:
        self.n += 1
        self.closed += int(c.closed)
        self.vertices += c.n_input
        minx, maxx, miny, maxy = c.box
        self.box = [min(self.box[0], minx), min(self.box[1], miny), max(self.box[2], maxx), max(self.box[3], maxy)]

    def bounds(self) -> tuple[float, float, float, float]:
        """(minx, miny, maxx, maxy) of every row, zeros when there is none."""
        return (0.0, 0.0, 0.0, 0.0) if self.n == 0 else (self.box[0], self.box[1], self.box[2], self.box[3])


def unwritable_reason(exc: BaseException) -> str | None:
    """Why a write failed when the file system refused it (else None: a bug, not the disk)."""
    text = str(exc).lower()
    if isinstance(exc, sqlite3.OperationalError) and any(m in text for m in _UNWRITABLE_MESSAGES):
        return str(exc)
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EDQUOT, errno.EPERM):
        return os.strerror(exc.errno or 0)
    return None


class CCSStore:
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

    Raises
    ------
    StoreError
        The file is not a ccsm store, is of another format, or cannot be opened.
    """

    def __init__(self, path: str | os.PathLike[str], *, readonly: bool = False, mmap_bytes: int = 0) -> None:
        self.path = Path(path)
        self.readonly = readonly
        self.mmap_bytes = int(mmap_bytes)
        self._local = threading.local()
        self._lock = threading.Lock()
        if not readonly:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        elif not self.path.exists():
            raise StoreError(f"store {self.path.name} does not exist")
        try:
            con = self._con()
            if not readonly:
                con.executescript(_SCHEMA + ISSUES_SCHEMA)
                row = con.execute("SELECT value FROM store_meta WHERE key='format'").fetchone()
                if row is None:
                    con.execute("INSERT OR IGNORE INTO store_meta VALUES ('format', ?)", (str(STORE_FORMAT),))
                    con.execute("INSERT OR IGNORE INTO store_meta VALUES ('version_counter', '0')")
                    con.commit()
            row = con.execute("SELECT value FROM store_meta WHERE key='format'").fetchone()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"store {self.path.name} cannot be opened: {exc}") from exc
        if row is None or int(row[0]) != STORE_FORMAT:
            raise StoreFormatError(
                f"store {self.path.name} has format {row[0] if row else 'unknown'}, expected {STORE_FORMAT}"
            )

    # -- connections -------------------------------------------------------------------------------------
    def _con(self) -> sqlite3.Connection:
        con: sqlite3.Connection | None = getattr(self._local, "con", None)
        if con is None:
            uri = f"file:{self.path}?mode={'ro' if self.readonly else 'rwc'}"
            con = sqlite3.connect(uri, uri=True, timeout=60.0, isolation_level=None, check_same_thread=False)
            if not self.readonly:
                con.execute("PRAGMA journal_mode=WAL")
            # NORMAL is durable for WAL across application crashes (kill -9); only a power cut may lose the
            # last commit, never corrupt the file.
            con.execute("PRAGMA synchronous=NORMAL")
            con.execute("PRAGMA busy_timeout=60000")
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

    # -- datasets ----------------------------------------------------------------------------------------
    def dataset_ids(self) -> list[str]:
        """Ids of the stored (ready) datasets, sorted."""
        return [r[0] for r in self._con().execute("SELECT id FROM datasets ORDER BY id")]

    def data_version(self, dataset: str) -> int | None:
        """The dataset's current data_version, or None if it is not stored."""
        row = self._con().execute("SELECT data_version FROM datasets WHERE id=?", (dataset,)).fetchone()
        return None if row is None else int(row[0])

    def source_hash_of(self, dataset: str) -> str | None:
        """The stored source hash of a dataset, or None."""
        row = self._con().execute("SELECT source_hash FROM datasets WHERE id=?", (dataset,)).fetchone()
        return None if row is None else str(row[0])

    def dataset(self, dataset: str) -> DatasetInfo:
        """Metadata of a stored dataset.

        Raises
        ------
        UnknownLayer
            No dataset of that id is stored.
        """
        con = self._con()
        con.row_factory = sqlite3.Row
        try:
            row = con.execute("SELECT * FROM datasets WHERE id=?", (dataset,)).fetchone()
        finally:
            con.row_factory = None
        if row is None:
            raise UnknownLayer(f"unknown dataset {dataset!r}")
        return DatasetInfo(
            id=row["id"],
            name=row["name"],
            source=row["source"],
            source_hash=row["source_hash"],
            params=json.loads(row["params"]),
            data_version=int(row["data_version"]),
            built_at=float(row["built_at"]),
            build_seconds=float(row["build_seconds"]),
            working_crs=row["working_crs"],
            source_crs=row["source_crs"],
            interval=row["interval"],
            bounds_3857=(row["minx"], row["miny"], row["maxx"], row["maxy"]),
            n_contours=int(row["n_contours"]),
            n_closed=int(row["n_closed"]),
            n_vertices=int(row["n_vertices"]),
            source_scale=float(row["source_scale"]),
            target_scale=float(row["target_scale"]),
            ladder=_array(row["ladder"]),
            bad_features=json.loads(row["bad_features"]),
        )

    def save(
        self,
        dataset: str,
        meta: NewDataset,
        contours: Iterable[NewContour],
        progress: Callable[[int, int], None] | None = None,
        *,
        only_if_building: bool = False,
        labels: LabelPlacer | None = None,
    ) -> DatasetInfo:
        """Write a dataset, replacing any previous version, in one transaction.

        Inside the transaction the old rows are deleted and the new ones inserted as ``contours`` yields
        them (a generator keeps only one batch of rows in memory; the dataset's row, with its bounds and
        counts, goes in last). An exception (or a killed process) before COMMIT leaves the previous version
        untouched. With ``only_if_building`` the write happens only while the dataset's build is still
        recorded (checked inside the transaction), so a dataset deleted during its build never comes back:
        BuildCancelled is raised instead. ``progress`` gets (rows written, rows known so far). ``labels``, when
        given, is called after the rows and the dataset's row are in, and its anchors are written in the same
        transaction (with the new ``data_version``).
        """
        with self._write() as cur:
            if only_if_building and not self._is_building(cur, dataset):
                raise BuildCancelled(f"dataset {dataset!r} was deleted while it built")
            self._delete_rows(cur, dataset)
            counts = _RowTally()
            step = 256
            for c in contours:
                cur.execute(
                    "INSERT INTO contours(dataset, contour_id, elevation, closed, grp, vanish_scale, "
                    "length_m, n_rows, n_input, base, top, original, original_w, t_at_scale, sim_t, sim, sig, "
                    "sig_top, sig_original) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    _contour_row(dataset, c),
                )
                fid = cur.lastrowid
                cur.execute("INSERT INTO contour_rtree VALUES (?,?,?,?,?,?)", (fid, *c.box, dataset))
                if c.issues:
                    insert_issues(cur, dataset, int(fid or 0), c.issues)
                for kind, k, blobs, box in _pieces(c):
                    marks = ",".join("?" * len(blobs))
                    cur.execute(f"INSERT INTO {kind}_pieces VALUES (NULL,?,?,{marks})", (fid, k, *blobs))
                    cur.execute(f"INSERT INTO {kind}_piece_rtree VALUES (?,?,?,?,?,?)", (cur.lastrowid, *box, dataset))
                counts.add(c)
                if progress and counts.n % step == 0:
                    progress(counts.n, counts.n)
            if progress:
                progress(counts.n, counts.n)
            counter = int(cur.execute("SELECT value FROM store_meta WHERE key='version_counter'").fetchone()[0]) + 1
            cur.execute("UPDATE store_meta SET value=? WHERE key='version_counter'", (str(counter),))
            cur.execute(
                "INSERT INTO datasets VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                (
                    dataset,
                    meta.name,
                    meta.source,
                    meta.source_hash,
                    json.dumps(meta.params, sort_keys=True, default=str),
                    counter,
                    time.time(),
                    float(meta.build_seconds),
                    meta.working_crs,
                    meta.source_crs,
                    None if meta.interval is None else float(meta.interval),
                    *counts.bounds(),
                    counts.n,
                    counts.closed,
                    counts.vertices,
                    float(meta.source_scale),
                    float(meta.target_scale),
                    _blob(np.asarray(meta.ladder, dtype=np.float64)),
                    json.dumps(meta.bad_features),
                ),
            )
            if labels is not None:
                placed = labels()
                self._insert_labels(cur, dataset, counter, placed)
                for fid, reason in placed.issues:
                    insert_issues(cur, dataset, fid, [("labels", reason)])
            cur.execute("DELETE FROM builds WHERE dataset=?", (dataset,))
        return self.dataset(dataset)

    @staticmethod
    def _insert_labels(cur: sqlite3.Cursor, dataset: str, data_version: int, labels: StoredLabels) -> None:
        cur.execute(
            "INSERT INTO labels VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                dataset,
                data_version,
                float(labels.last_zoom),
                len(labels.fid),
                _blob(labels.xy),
                _blob(labels.angle),
                _blob(labels.min_zoom),
                np.asarray(labels.fid, dtype="<i8").tobytes(),
                np.asarray(labels.rank, dtype="<i8").tobytes(),
                _blob(labels.elevation),
                json.dumps(list(labels.text)),
                _blob(labels.box_px),
            ),
        )

    def labels(self, dataset: str) -> StoredLabels | None:
        """The label anchors stored with the dataset's current version, or None (none were placed at build)."""
        columns = "data_version, last_zoom, xy, angle, min_zoom, fid, rank, elevation, text, box_px"
        row = self._con().execute(f"SELECT {columns} FROM labels WHERE dataset=?", (dataset,)).fetchone()
        if row is None:
            return None
        return StoredLabels(
            data_version=int(row[0]),
            last_zoom=float(row[1]),
            xy=_array(row[2], 2),
            angle=_array(row[3]),
            min_zoom=_array(row[4]),
            fid=np.frombuffer(row[5], dtype="<i8"),
            rank=np.frombuffer(row[6], dtype="<i8"),
            elevation=_array(row[7]),
            text=list(json.loads(row[8])),
            box_px=_array(row[9], 2),
        )

    def contour_issues(self, dataset: str) -> tuple[list[dict[str, Any]], int]:
        """The dataset's contours served without part of their build (``fid``, ``id``, ``step``, ``reason``;
        the first :data:`engine.store.issues.REPORTED_ISSUES`) and how many there are."""
        return read_issues(self._con(), dataset)

    @staticmethod
    def _delete_rows(cur: sqlite3.Cursor, dataset: str) -> None:
        cur.execute(
            "DELETE FROM contour_rtree WHERE fid IN (SELECT fid FROM contours WHERE dataset=?)", (dataset,)
        )
        for kind in PIECE_KINDS:
            pieces = f"SELECT piece FROM {kind}_pieces WHERE fid IN (SELECT fid FROM contours WHERE dataset=?)"
            cur.execute(f"DELETE FROM {kind}_piece_rtree WHERE piece IN ({pieces})", (dataset,))
            cur.execute(f"DELETE FROM {kind}_pieces WHERE piece IN ({pieces})", (dataset,))
        cur.execute("DELETE FROM contours WHERE dataset=?", (dataset,))
        cur.execute("DELETE FROM labels WHERE dataset=?", (dataset,))
        delete_issues(cur, dataset)
        cur.execute("DELETE FROM datasets WHERE id=?", (dataset,))

    def delete(self, dataset: str) -> bool:
        """Remove a dataset and its build status; True if it was stored."""
        with self._write() as cur:
            existed = cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
            self._delete_rows(cur, dataset)
            cur.execute("DELETE FROM builds WHERE dataset=?", (dataset,))
        return existed

    def delete_any(self, dataset: str) -> bool:
        """Remove a dataset, stored or only building or failed; True if there was either."""
        with self._write() as cur:
            stored = cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
            build = cur.execute("SELECT 1 FROM builds WHERE dataset=?", (dataset,)).fetchone() is not None
            self._delete_rows(cur, dataset)
            cur.execute("DELETE FROM builds WHERE dataset=?", (dataset,))
        return stored or build

    # -- id reservation ----------------------------------------------------------------------------------
    @staticmethod
    def _is_building(cur: sqlite3.Cursor, dataset: str) -> bool:
        row = cur.execute("SELECT state FROM builds WHERE dataset=?", (dataset,)).fetchone()
        return row is not None and row[0] == "building"

    @staticmethod
    def _taken(cur: sqlite3.Cursor, dataset: str) -> bool:
        return (
            cur.execute("SELECT 1 FROM datasets WHERE id=?", (dataset,)).fetchone() is not None
            or cur.execute("SELECT 1 FROM builds WHERE dataset=?", (dataset,)).fetchone() is not None
        )

    @staticmethod
    def _insert_build(cur: sqlite3.Cursor, dataset: str, total: int) -> None:
        now = time.time()
        cur.execute(
            "INSERT INTO builds VALUES (?,?,?,?,?,?,?,?,?)",
            (dataset, "building", 0, int(total), None, os.getpid(), host_name(), now, now),
        )

    def reserve(self, dataset: str, total: int = 0) -> bool:
        """Claim a new dataset id for a build, atomically across threads and processes.

        True when the id was free (neither stored nor building nor failed): a 'building' row now holds it.
        """
        with self._write() as cur:
            if self._taken(cur, dataset):
                return False
            self._insert_build(cur, dataset, total)
        return True

    def reserve_free(self, base: str, total: int = 0) -> str:
        """Claim ``base``, else ``base-2``, ``base-3``, ... (the first free one), in one transaction."""
        with self._write() as cur:
            ident, n = base, 2
            while self._taken(cur, ident):
                ident, n = f"{base}-{n}", n + 1
            self._insert_build(cur, ident, total)
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

    # -- contours ----------------------------------------------------------------------------------------
    def query(self, dataset: str, bounds_3857: Sequence[float]) -> list[int]:
        """fids of the dataset's contours whose extent meets an EPSG:3857 rectangle (R*Tree lookup)."""
        minx, miny, maxx, maxy = (float(v) for v in bounds_3857)
        # The dataset is an auxiliary column of the R*Tree: filtered after the spatial search, so the cost
        # follows the contours near the rectangle, not the size of the store.
        cur = self._con().execute(
            "SELECT fid FROM contour_rtree WHERE maxx >= ? AND minx <= ? AND maxy >= ? AND miny <= ? "
            "AND dataset = ? ORDER BY fid",
            (minx, maxx, miny, maxy, dataset),
        )
        return list(chain.from_iterable(cur))

    def pieces_meeting(
        self, dataset: str, bounds_3857: Sequence[float], kind: str, fid_range: tuple[int, int] | None = None
    ) -> StoredPieces:
        """The dataset's pieces of one kind (``ccs`` or ``original``) whose rows' extent meets an EPSG:3857
        rectangle, sorted by fid and k.

        ``fid_range`` (first, last): the dataset's contours are exactly the fids first to last, so its pieces
        are told apart by their fid instead of the R*Tree's dataset column, which costs a look-up of every
        candidate in the R*Tree's own row table (a quarter of the query at 64× the sample).
        """
        minx, miny, maxx, maxy = (float(v) for v in bounds_3857)
        names = PIECE_KINDS[kind]
        mine = fid_range if fid_range is not None else (dataset,)
        rows = self._con().execute(pieces_sql(kind, fid_range is not None), (minx, maxx, miny, maxy, *mine)).fetchall()
        # Sorted here, not by SQL's ORDER BY, whose sorter copies every row with its blobs.
        fid = np.array([r[0] for r in rows], dtype=np.int64)
        k = np.array([r[1] for r in rows], dtype=np.int64)
        order = np.lexsort((k, fid))
        rows = [rows[i] for i in order.tolist()]
        fid, k = fid[order], k[order]
        n = np.array([len(r[2]) // 16 for r in rows], dtype=np.int64)  # the first column holds (x, y) float64
        arrays = tuple(_column(name, b"".join([r[2 + j] for r in rows])) for j, name in enumerate(names))
        return StoredPieces(fid, k, n, arrays)

    def load_heads(self, fids: Sequence[int]) -> list[ContourHead]:
        """The per-contour columns of contours by fid, without their rows (in the order given; unknown fids
        are skipped)."""
        out: dict[int, ContourHead] = {}
        con = self._con()
        for i in range(0, len(fids), 500):
            chunk = list(fids[i : i + 500])
            marks = ",".join("?" * len(chunk))
            sql = f"SELECT fid, elevation, vanish_scale, t_at_scale FROM contours WHERE fid IN ({marks})"
            for r in con.execute(sql, chunk):
                vanish = math.inf if r[2] is None else float(r[2])
                out[r[0]] = ContourHead(r[0], float(r[1]), vanish, _array(r[3]))
        return [out[f] for f in fids if f in out]

    def dataset_heads(
        self, dataset: str
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The per-contour columns of every contour of a dataset, in fid order, as arrays: fid, elevation,
        vanishing scale (inf: never vanishes) and the (n, S) t tables."""
        rows = self._con().execute(
            "SELECT fid, elevation, vanish_scale, t_at_scale FROM contours WHERE dataset=? ORDER BY fid", (dataset,)
        ).fetchall()
        fid = np.array([r[0] for r in rows], dtype=np.int64)
        elevation = np.array([r[1] for r in rows], dtype=np.float64)
        vanish = np.array([math.inf if r[2] is None else r[2] for r in rows], dtype=np.float64)
        width = len(rows[0][3]) // 8 if rows else 1
        tables = np.frombuffer(b"".join([r[3] for r in rows]), dtype="<f8").reshape(len(rows), width)
        return fid, elevation, vanish, tables.astype(np.float64)

    def all_fids(self, dataset: str) -> list[int]:
        """Every contour fid of a dataset, in input order."""
        return [
            r[0]
            for r in self._con().execute("SELECT fid FROM contours WHERE dataset=? ORDER BY fid", (dataset,))
        ]

    def elevations(self, dataset: str) -> NDArray[np.float64]:
        """The distinct elevations of a dataset's contours."""
        rows = self._con().execute("SELECT DISTINCT elevation FROM contours WHERE dataset=?", (dataset,))
        return np.array([r[0] for r in rows], dtype=np.float64)

    def load(self, fids: Sequence[int]) -> list[ContourRecord]:
        """Decode contour rows by fid (in the order given; unknown fids are skipped)."""
        out: dict[int, ContourRecord] = {}
        con = self._con()
        for i in range(0, len(fids), 500):
            chunk = list(fids[i : i + 500])
            marks = ",".join("?" * len(chunk))
            for r in con.execute(
                "SELECT fid, dataset, contour_id, elevation, closed, grp, vanish_scale, length_m, base, top, "
                f"original, original_w, t_at_scale, sim_t, sim, sig, sig_top, sig_original FROM contours "
                f"WHERE fid IN ({marks})",
                chunk,
            ):
                out[r[0]] = ContourRecord(
                    fid=r[0],
                    dataset=r[1],
                    contour_id=r[2],
                    elevation=r[3],
                    closed=bool(r[4]),
                    group=r[5],
                    vanish_scale=math.inf if r[6] is None else float(r[6]),
                    length_m=r[7],
                    base=_array(r[8], 2),
                    top=_array(r[9], 2),
                    original=_array(r[10], 2),
                    original_w=_array(r[11], 2),
                    t_at_scale=_array(r[12]),
                    sim_t=_array(r[13]),
                    sim=_array(r[14]),
                    sig=np.frombuffer(r[15], dtype="<f4"),
                    sig_top=np.frombuffer(r[16], dtype="<f4"),
                    sig_original=np.frombuffer(r[17], dtype="<f4"),
                )
        return [out[f] for f in fids if f in out]

    # -- build status ------------------------------------------------------------------------------------
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
            cur.execute("DELETE FROM builds WHERE dataset=?", (dataset,))

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

    def integrity_ok(self) -> bool:
        """SQLite's own integrity check of the file."""
        return self._con().execute("PRAGMA integrity_check").fetchone()[0] == "ok"
