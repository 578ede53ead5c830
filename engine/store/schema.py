"""The layout of a store file: its tables (SQL) and its format number (applied by :mod:`engine.store.connection`).

Every table is here, the build bookkeeping's ``builds`` table too (:mod:`engine.store.builds`), so a store
file is made in one script and its format is one number.
"""

from __future__ import annotations

#: Bumped whenever the layout of the file changes; a store of another format is refused.
STORE_FORMAT = 4
#: Rows of a stored piece of a contour's rows (piece k holds rows k * PIECE_ROWS to (k + 1) * PIECE_ROWS, both
#: included): a tile of a dataset too large to hold in memory reads only the pieces it meets. A multiple of the
#: tiles' chunk rows (engine.serve.pieces checks it), so a piece's chunks are the whole line's.
PIECE_ROWS = 256
#: The kinds of stored pieces: of the CCS rows (columns base, top, sig, sig_top) and of the original (columns
#: original, sig_original); kind ``k`` is stored in tables ``k_pieces`` and ``k_piece_rtree``.
PIECE_KINDS = {"ccs": ("base", "top", "sig", "sig_top"), "original": ("original", "sig_original")}


#: SQL that brings a store of an older format to this one, by the format it has: format 3 kept a dataset's rows
#: under its own id, which ``rows_id`` now names (its first rebuild moves them to a row id of their own).
MIGRATIONS: dict[int, tuple[str, ...]] = {
    3: (
        "ALTER TABLE datasets ADD COLUMN rows_id TEXT NOT NULL DEFAULT ''",
        "UPDATE datasets SET rows_id = id",
        "UPDATE store_meta SET value = '4' WHERE key = 'format'",
    ),
}


def _piece_tables(kind: str) -> str:
    """The tables of one kind of stored pieces (:data:`PIECE_KINDS`): its pieces, indexed by fid, and their R*Tree."""
    columns = ",\n".join(f"    {name} BLOB NOT NULL" for name in PIECE_KINDS[kind])
    return f"""CREATE TABLE IF NOT EXISTS {kind}_pieces(
    piece INTEGER PRIMARY KEY,
    fid INTEGER NOT NULL,
    k INTEGER NOT NULL,
{columns}
);
CREATE INDEX IF NOT EXISTS {kind}_pieces_fid ON {kind}_pieces(fid);
CREATE VIRTUAL TABLE IF NOT EXISTS {kind}_piece_rtree USING rtree(piece, minx, maxx, miny, maxy, +dataset TEXT);
"""


#: Written from PIECE_KINDS, so the tables and the columns the store reads and writes cannot drift apart.
_PIECE_TABLES = "".join(_piece_tables(kind) for kind in PIECE_KINDS)

SCHEMA = f"""
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
    bad_features TEXT NOT NULL,
    -- The id the dataset's contour rows are stored under (engine/store/staging.py).
    rows_id TEXT NOT NULL
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
{_PIECE_TABLES}CREATE TABLE IF NOT EXISTS labels(
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
-- The contours served without part of their build, and why (engine/store/issues.py).
CREATE TABLE IF NOT EXISTS contour_issues(
    dataset TEXT NOT NULL,
    fid INTEGER NOT NULL,
    step TEXT NOT NULL,
    reason TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS contour_issues_dataset ON contour_issues(dataset);
"""

